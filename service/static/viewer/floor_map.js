// Top-down floor maps in metres, as SVG: one camera's floor frame, or the site frame of many.
// Map x runs right and y up (the floor frames of DESIGN.md); SVG's y runs down, so y is negated.

import { fmt, fmtPair, svg } from "./dom.js";
import { fovRadiusM, niceStep } from "./geometry.js";

let clipCounter = 0;

/** Bounds {xmin, xmax, ymin, ymax} m: a square around (cx, cy) with half side `half`. */
export function squareBounds(cx, cy, half) {
  return { xmin: cx - half, xmax: cx + half, ymin: cy - half, ymax: cy + half };
}

/** `bounds` widened (about its centre) to the aspect ratio of the drawing area `rect`. */
function fitAspect(bounds, rect) {
  if (!(rect.width > 0 && rect.height > 0)) return bounds;
  const width = bounds.xmax - bounds.xmin;
  const height = bounds.ymax - bounds.ymin;
  const aspect = rect.width / rect.height;
  const cx = (bounds.xmin + bounds.xmax) / 2;
  const cy = (bounds.ymin + bounds.ymax) / 2;
  const half = [Math.max(width, height * aspect) / 2, Math.max(height, width / aspect) / 2];
  return { xmin: cx - half[0], xmax: cx + half[0], ymin: cy - half[1], ymax: cy + half[1] };
}

function gridLayer(bounds, step, fontM) {
  const layer = svg("g", { class: "grid" });
  const { xmin, xmax, ymin, ymax } = bounds;
  for (let x = Math.ceil(xmin / step) * step; x <= xmax; x += step) {
    layer.append(svg("line", { class: x === 0 ? "grid-line zero" : "grid-line", x1: x, y1: -ymax, x2: x, y2: -ymin }));
    layer.append(svg("text", { class: "grid-label", x: x + fontM * 0.2, y: -ymin - fontM * 0.3, "font-size": fontM }, [`${+x.toFixed(6)}`]));
  }
  for (let y = Math.ceil(ymin / step) * step; y <= ymax; y += step) {
    layer.append(svg("line", { class: y === 0 ? "grid-line zero" : "grid-line", x1: xmin, y1: -y, x2: xmax, y2: -y }));
    layer.append(svg("text", { class: "grid-label", x: xmin + fontM * 0.2, y: -y - fontM * 0.3, "font-size": fontM }, [`${+y.toFixed(6)}`]));
  }
  return layer;
}

function cameraLayer(entry, fontM, ringStep) {
  const { camera, origin, yawDeg, showRings } = entry;
  const [ox, oy] = origin;
  const fov = fovRadiusM(camera);
  const layer = svg("g", { class: "camera", "data-camera": camera.id });
  if (showRings) {
    for (let r = ringStep; r < fov; r += ringStep) {
      layer.append(svg("circle", { class: "ring", "data-radius-m": +r.toFixed(6), cx: ox, cy: -oy, r }));
      layer.append(svg("text", { class: "ring-label", x: ox + r * Math.SQRT1_2, y: -oy + r * Math.SQRT1_2, "font-size": fontM * 0.8 }, [`${+r.toFixed(6)} m`]));
    }
  }
  layer.append(svg("circle", { class: "fov", "data-radius-m": fov, cx: ox, cy: -oy, r: fov }));
  const yaw = (yawDeg * Math.PI) / 180;
  const arrow = fontM * 2.5;
  for (const [name, angle] of [["x", yaw], ["y", yaw + Math.PI / 2]]) {
    const tip = [ox + arrow * Math.cos(angle), oy + arrow * Math.sin(angle)];
    layer.append(svg("line", { class: `axis axis-${name}`, x1: ox, y1: -oy, x2: tip[0], y2: -tip[1] }));
    layer.append(svg("text", { class: "axis-label", x: tip[0], y: -tip[1], "font-size": fontM * 0.8 }, [name]));
  }
  const s = fontM * 0.45;
  layer.append(svg("rect", { class: "camera-mark", x: ox - s, y: -oy - s, width: 2 * s, height: 2 * s }));
  layer.append(svg("text", { class: "camera-label", x: ox + s * 1.5, y: -oy + s * 3, "font-size": fontM }, [camera.id]));
  return layer;
}

function peopleLayer(people, fontM) {
  const layer = svg("g", { class: "people" });
  for (const person of people) {
    const [x, y] = person.xy;
    layer.append(svg("circle", {
      class: "person", "data-camera": person.cameraId, "data-index": person.index,
      "data-x": x, "data-y": y, cx: x, cy: -y, r: fontM * 0.4,
    }));
    layer.append(svg("text", { class: "person-label", x: x + fontM * 0.6, y: -y - fontM * 0.3, "font-size": fontM },
                     [`${person.label} ${fmtPair(person.xy, 2)}`]));
  }
  return layer;
}

/**
 * Draw a floor map into the <svg> `root` (contents replaced).
 * cameras: [{camera, origin: [x, y] m, yawDeg, showRings}]; people: [{xy: [x, y] m, label, cameraId,
 * index}]; bounds: {xmin, xmax, ymin, ymax} m.
 */
export function drawMap(root, { cameras, people, bounds: wanted }) {
  const rect = root.getBoundingClientRect();
  const bounds = fitAspect(wanted, rect);
  const width = bounds.xmax - bounds.xmin;
  const height = bounds.ymax - bounds.ymin;
  // Text about 13 screen px high, whatever the map's scale.
  const fontM = rect.width > 0 ? (13 * width) / rect.width : Math.max(width, height) / 40;
  const step = niceStep(Math.min(width, height), 8);
  const ringStep = Math.max(1, step);
  root.replaceChildren();
  root.setAttribute("viewBox", `${bounds.xmin} ${-bounds.ymax} ${bounds.xmax - bounds.xmin} ${bounds.ymax - bounds.ymin}`);
  root.dataset.bounds = JSON.stringify(bounds);
  clipCounter += 1;
  const clipId = `map-clip-${clipCounter}`;
  root.append(svg("defs", {}, [svg("clipPath", { id: clipId }, [svg("rect", {
    x: bounds.xmin, y: -bounds.ymax, width: bounds.xmax - bounds.xmin, height: bounds.ymax - bounds.ymin,
  })])]));
  const content = svg("g", { "clip-path": `url(#${clipId})` });
  content.append(svg("rect", { class: "map-background", x: bounds.xmin, y: -bounds.ymax,
                               width: bounds.xmax - bounds.xmin, height: bounds.ymax - bounds.ymin }));
  content.append(gridLayer(bounds, step, fontM));
  for (const entry of cameras) content.append(cameraLayer(entry, fontM, ringStep));
  content.append(peopleLayer(people, fontM));
  root.append(content);
  root.append(svg("text", { class: "scale-label", x: bounds.xmax - fontM * 0.5, y: -bounds.ymax + fontM * 1.2,
                            "font-size": fontM, "text-anchor": "end" }, [`grid ${fmt(step, step < 1 ? 1 : 0)} m`]));
}
