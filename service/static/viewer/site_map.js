// The live site map as SVG: the floor map of floor_map.js (grid, each camera's field of view,
// people) with a site's zones and their counts, its counting lines with their in/out tallies, and
// the recent trail of every track. Site frame in metres, x right, y up (SVG y is negated).

import { fmt, pointsAttr, svg } from "./dom.js";
import { drawMap } from "./floor_map.js";

const CAMERA_REACH_M = 5; // the map shows at least this much floor round every camera

/** Bounds {xmin, xmax, ymin, ymax} m holding the cameras (with some floor round them, or their
 *  whole views with `withViews`), zones, lines and people, plus a margin. */
export function siteBounds({ cameras, zones, lines, people, withViews = false }) {
  const xs = [];
  const ys = [];
  for (const { origin: [x, y] } of cameras) {
    xs.push(x - CAMERA_REACH_M, x + CAMERA_REACH_M);
    ys.push(y - CAMERA_REACH_M, y + CAMERA_REACH_M);
  }
  const points = [...zones.flatMap((z) => z.polygon), ...lines.flatMap((l) => [l.from, l.to]),
                  ...people.map((p) => p.xy), ...(withViews ? cameras.flatMap((c) => c.view ?? []) : [])];
  for (const [x, y] of points) {
    xs.push(x);
    ys.push(y);
  }
  if (!xs.length) return { xmin: -5, xmax: 5, ymin: -5, ymax: 5 };
  const margin = 0.5;
  return { xmin: Math.min(...xs) - margin, xmax: Math.max(...xs) + margin,
           ymin: Math.min(...ys) - margin, ymax: Math.max(...ys) + margin };
}

/** The text size (m) that drawMap chose: about 13 screen px. */
function fontSizeM(root) {
  const [, , width] = root.getAttribute("viewBox").split(" ").map(Number);
  const rect = root.getBoundingClientRect();
  return rect.width > 0 ? (13 * width) / rect.width : width / 40;
}

function zoneLayer(zones, counts, fontM) {
  const layer = svg("g", { class: "zones" });
  for (const zone of zones) {
    const count = counts[zone.id]?.count ?? 0;
    layer.append(svg("polygon", { class: "zone", "data-zone": zone.id, "data-count": count,
                                  points: pointsAttr(zone.polygon.map(([x, y]) => [x, -y])) }));
    const cx = zone.polygon.reduce((s, p) => s + p[0], 0) / zone.polygon.length;
    const top = Math.max(...zone.polygon.map((p) => p[1]));
    layer.append(svg("text", { class: "zone-label", "data-zone": zone.id, x: cx, y: -top + fontM * 1.2,
                               "font-size": fontM, "text-anchor": "middle" }, [`${zone.id}: ${count}`]));
  }
  return layer;
}

function lineLayer(lines, tallies, fontM) {
  const layer = svg("g", { class: "count-lines" });
  for (const line of lines) {
    const [[x1, y1], [x2, y2]] = [line.from, line.to];
    const tally = tallies[line.id] ?? { in: 0, out: 0 };
    layer.append(svg("line", { class: "count-line", "data-line": line.id, "data-in": tally.in,
                               "data-out": tally.out, x1, y1: -y1, x2, y2: -y2 }));
    // `in` is a crossing from the line's left to its right: the arrow points to the right side.
    const length = Math.hypot(x2 - x1, y2 - y1) || 1;
    const right = [(y2 - y1) / length, -(x2 - x1) / length];
    const mid = [(x1 + x2) / 2, (y1 + y2) / 2];
    const tip = [mid[0] + right[0] * fontM * 2, mid[1] + right[1] * fontM * 2];
    layer.append(svg("line", { class: "in-arrow", x1: mid[0], y1: -mid[1], x2: tip[0], y2: -tip[1] }));
    layer.append(svg("text", { class: "line-label", "data-line": line.id, x: x2 + fontM * 0.3, y: -y2,
                               "font-size": fontM }, [`${line.id} in ${tally.in} · out ${tally.out}`]));
  }
  return layer;
}

function trailLayer(trails) {
  const layer = svg("g", { class: "trails" });
  for (const [trackId, points] of trails) {
    if (points.length < 2) continue;
    layer.append(svg("polyline", { class: "trail", "data-track": trackId,
                                   points: pointsAttr(points.map(([x, y]) => [x, -y])) }));
  }
  return layer;
}

/**
 * Draw the live map into the <svg> `root` (contents replaced).
 * cameras: [{camera, origin: [x, y], yawDeg, view: [[x, y], ...] m or null}]; zones: [{id, polygon}]; lines: [{id, from, to}];
 * occupancy: the service's occupancy answer; trails: Map track id -> [[x, y], ...] m, oldest first;
 * withViews: frame the cameras' whole views rather than the site's zones, lines and people.
 */
export function drawSiteMap(root, { cameras, zones, lines, occupancy, trails, withViews = false }) {
  const people = (occupancy?.people ?? []).filter((p) => p.position_m).map((p, index) => ({
    xy: p.position_m, label: p.track_id, cameraId: (p.cameras ?? []).join(","), index,
  }));
  const bounds = siteBounds({ cameras, zones, lines, people, withViews });
  drawMap(root, { cameras: cameras.map((c) => ({ ...c, showRings: false })), people, bounds });
  const fontM = fontSizeM(root);
  // The floor a camera can place people on, as the service outlines it (else the fov circle).
  for (const { camera, view } of cameras) {
    const circle = root.querySelector(`g.camera[data-camera="${CSS.escape(camera.id)}"] circle.fov`);
    if (circle && view?.length > 2) {
      circle.replaceWith(svg("polygon", { class: "fov view", "data-camera": camera.id,
                                          points: pointsAttr(view.map(([x, y]) => [x, -y])) }));
    }
  }
  root.querySelectorAll("circle.person").forEach((dot, i) => {
    dot.dataset.track = people[i].label;
  });
  const content = root.querySelector("g[clip-path]");
  const peopleLayer = content.querySelector("g.people");
  content.insertBefore(zoneLayer(zones, occupancy?.zones ?? {}, fontM), peopleLayer);
  content.insertBefore(lineLayer(lines, occupancy?.lines ?? {}, fontM), peopleLayer);
  content.insertBefore(trailLayer(trails), peopleLayer);
  root.dataset.count = String(occupancy?.count ?? 0);
  root.dataset.time = occupancy?.time === undefined ? "" : String(occupancy.time);
}

/** Speed (m/s) of a velocity [vx, vy], for display. */
export function speedText(velocity) {
  return velocity ? fmt(Math.hypot(velocity[0], velocity[1]), 2) : "–";
}
