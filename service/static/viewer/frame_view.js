// The frame with its detections and the calibration check drawn over it, as SVG in frame pixels.
// The viewBox starts at (-0.5, -0.5): pixel centres sit at integer coordinates, as in the API.

import { fmt, pointsAttr, svg } from "./dom.js";
import { floorPointToPixel, floorRingPixels, fovRadiusM, scaledCamera, thetaMaxDeg, thetaToRadius } from "./geometry.js";

const RING_LABEL_PHI = -Math.PI / 4; // ring labels sit towards the lower right of the nadir

/** Floor rings every metre out to the field of view, the nadir, the x/y axes and the θmax circle. */
export function calibrationLayer(camera, frameWh, fontPx) {
  const scaled = scaledCamera(camera, frameWh);
  const layer = svg("g", { class: "calibration" });
  const [u0, v0] = scaled.principal_point;
  const rMax = thetaToRadius(thetaMaxDeg(scaled) * Math.PI / 180, scaled.kb);
  layer.append(svg("ellipse", {
    class: "theta-max", cx: u0, cy: v0, rx: scaled.focal_px[0] * rMax, ry: scaled.focal_px[1] * rMax,
  }));
  // Every metre out to the field of view; where the rings crowd towards the horizon, only every
  // fifth, and none where even those would merge.
  const maxRing = Math.floor(fovRadiusM(scaled));
  const minGapPx = Math.max(...frameWh) / 150;
  const gapPx = (inner, outer) => {
    const a = floorPointToPixel(scaled, inner, 0);
    const b = floorPointToPixel(scaled, outer, 0);
    return a && b ? Math.hypot(b[0] - a[0], b[1] - a[1]) : 0;
  };
  for (let radius = 1; radius <= maxRing; radius += 1) {
    const major = radius % 5 === 0;
    const gap = gapPx(radius - 1, radius);
    const majorGap = major ? gapPx(radius - 5, radius) : 0;
    if (gap < minGapPx && majorGap < minGapPx) continue;
    for (const run of floorRingPixels(scaled, radius)) {
      layer.append(svg("polyline", {
        class: major ? "ring major" : "ring", "data-radius-m": radius, points: pointsAttr(run),
      }));
    }
    if (gap >= fontPx * 1.2 || majorGap >= fontPx * 1.2) {
      const at = floorPointToPixel(scaled, radius * Math.cos(RING_LABEL_PHI), radius * Math.sin(RING_LABEL_PHI));
      if (at) layer.append(svg("text", { class: "ring-label", x: at[0], y: at[1], "font-size": fontPx * 0.8 }, [`${radius} m`]));
    }
  }
  const nadir = floorPointToPixel(scaled, 0, 0);
  for (const [name, x, y] of [["x", 1, 0], ["y", 0, 1]]) {
    const tip = floorPointToPixel(scaled, x, y);
    if (!tip) continue;
    layer.append(svg("line", { class: `axis axis-${name}`, x1: nadir[0], y1: nadir[1], x2: tip[0], y2: tip[1] }));
    layer.append(svg("text", { class: "axis-label", x: tip[0], y: tip[1], "font-size": fontPx }, [name]));
  }
  layer.append(svg("circle", { class: "nadir", cx: nadir[0], cy: nadir[1], r: fontPx * 0.25 }));
  return layer;
}

/** Box polygons from the API's corners, foot points, and score labels. */
function detectionsLayer(detections, fontPx) {
  const layer = svg("g", { class: "detections" });
  detections.forEach((det, index) => {
    layer.append(svg("polygon", {
      class: "box", "data-index": index, "data-score": det.score, points: pointsAttr(det.corners),
    }));
  });
  detections.forEach((det, index) => {
    if (!det.foot_px) return;
    const [u, v] = det.foot_px;
    layer.append(svg("circle", { class: "foot", "data-index": index, cx: u, cy: v, r: fontPx * 0.3 }));
    layer.append(svg("text", { class: "box-label", x: u + fontPx * 0.4, y: v - fontPx * 0.4, "font-size": fontPx },
                     [`#${index + 1} ${fmt(det.score, 2)}`]));
  });
  return layer;
}

/**
 * Draw `frameUrl` (width × height px) with `result.detections` and, when `showRings`, the camera's
 * floor rings into the <svg> element `root` (its contents are replaced).
 */
export function drawFrame(root, { frameUrl, result, camera, showRings }) {
  const { width, height } = result.image;
  const fontPx = Math.max(width, height) / 60;
  root.replaceChildren();
  root.setAttribute("viewBox", `-0.5 -0.5 ${width} ${height}`);
  root.dataset.width = String(width);
  root.dataset.height = String(height);
  root.append(svg("image", { href: frameUrl, x: -0.5, y: -0.5, width, height, preserveAspectRatio: "none" }));
  if (showRings && camera) {
    try {
      root.append(calibrationLayer(camera, [width, height], fontPx));
    } catch (error) {
      root.append(svg("text", { class: "frame-error", x: 10, y: fontPx * 1.5, "font-size": fontPx }, [error.message]));
    }
  }
  root.append(detectionsLayer(result.detections, fontPx));
}
