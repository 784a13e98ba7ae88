// What the Calibrate mode draws over its frame, in frame pixels: the fitted camera's floor rings
// and each tape's fitted direction, the frame's fitted image circle and its centre, the masks, the ruler marks coloured by their residual, and the
// floor points the Check tool was clicked at. Sizes are in screen pixels, whatever the zoom.

import { fmt, pointsAttr, svg } from "./dom.js";
import { calibrationLayer } from "./frame_view.js";
import { floorPointToPixel, pixelToFloorPoint } from "./geometry.js";
import { maskProblem } from "./masks.js";

const GOOD_M = 0.01;   // a residual under this is click noise (green)
const FAIR_M = 0.03;   // under this it is worth a look (amber); above, red

/** The class of a mark's residual |err_m|: "good", "fair", "bad", or "none" before a fit. */
export function residualClass(errM) {
  if (errM === null || errM === undefined || !Number.isFinite(errM)) return "none";
  const size = Math.abs(errM);
  return size < GOOD_M ? "good" : size < FAIR_M ? "fair" : "bad";
}

/** Each ruler's direction on the floor by `camera` (scaled to the frame): the mean direction of its
 *  marks' floor points, drawn from the nadir to a little past its farthest mark. */
function tapeLayer(camera, marks, fontPx) {
  const layer = svg("g", { class: "tapes" });
  const rulers = new Map();
  for (const mark of marks) {
    if (mark.distance_m <= 0) continue;
    const xy = mark.x_m !== null ? [mark.x_m, mark.y_m] : pixelToFloorPoint(camera, mark.u, mark.v);
    if (!xy || Math.hypot(...xy) === 0) continue;
    const entry = rulers.get(mark.ruler) ?? { sx: 0, sy: 0, far: 0 };
    const d = Math.hypot(...xy);
    entry.sx += xy[0] / d;
    entry.sy += xy[1] / d;
    entry.far = Math.max(entry.far, mark.distance_m);
    rulers.set(mark.ruler, entry);
  }
  for (const [ruler, { sx, sy, far }] of rulers) {
    const phi = Math.atan2(sy, sx);
    const reach = far * 1.1 + 0.3;
    const points = [];
    for (let i = 0; i <= 60; i += 1) {
      const uv = floorPointToPixel(camera, (reach * i / 60) * Math.cos(phi), (reach * i / 60) * Math.sin(phi));
      if (uv) points.push(uv);
    }
    if (points.length < 2) continue;
    layer.append(svg("polyline", { class: "tape", "data-ruler": ruler, "data-azimuth-deg": phi * 180 / Math.PI,
                                   points: pointsAttr(points) }));
    const [u, v] = points[points.length - 1];
    layer.append(svg("text", { class: "tape-label", x: u, y: v, "font-size": fontPx }, [ruler || "(no ruler)"]));
  }
  return layer;
}

function masksLayer(masks, drawing, fontPx) {
  const layer = svg("g", { class: "masks" });
  masks.forEach((points, index) => {
    const bad = maskProblem(points, index) !== null;
    layer.append(svg("polygon", { class: bad ? "mask bad" : "mask", "data-mask": index, points: pointsAttr(points) }));
    const [u, v] = points[0];
    layer.append(svg("text", { class: "mask-label", x: u, y: v, "font-size": fontPx }, [`mask ${index + 1}`]));
  });
  if (drawing.length) {
    layer.append(svg("polyline", { class: "mask drawing", points: pointsAttr(drawing) }));
    for (const [u, v] of drawing) layer.append(svg("circle", { class: "mask-corner", cx: u, cy: v, r: fontPx * 0.3 }));
  }
  return layer;
}

const LABEL_ALL_SCALE = 1.5; // zoomed out below this (screen px per frame px), only marks that need a look are labelled

function marksLayer(marks, residuals, selected, fontPx, screenPerFrame) {
  const layer = svg("g", { class: "marks" });
  marks.forEach((mark, index) => {
    const residual = residuals.get(mark.id) ?? null;
    const nadir = mark.distance_m === 0;
    const kind = nadir ? "nadir-mark" : "mark";
    const group = svg("g", {
      class: `${kind} ${residualClass(residual?.err_m)}${mark.id === selected ? " selected" : ""}`,
      "data-drag": "mark", "data-mark-id": mark.id, "data-index": index, "data-u": mark.u, "data-v": mark.v,
    });
    const r = fontPx * 0.45;
    if (nadir) {
      group.append(svg("path", { d: `M ${mark.u - r * 1.6} ${mark.v} H ${mark.u + r * 1.6} M ${mark.u} ${mark.v - r * 1.6} V ${mark.v + r * 1.6}` }));
    }
    group.append(svg("circle", { cx: mark.u, cy: mark.v, r }));
    const label = nadir ? `${index + 1} · nadir` : `${index + 1} · ${fmt(mark.distance_m, 2)} m`;
    const text = !nadir && residual && Number.isFinite(residual.err_m)
      ? `${label} ${residual.err_m >= 0 ? "+" : "−"}${fmt(Math.abs(residual.err_m) * 100, 1)} cm` : label;
    const quiet = screenPerFrame < LABEL_ALL_SCALE && mark.id !== selected &&
      ["good", "none"].includes(residualClass(residual?.err_m)) && !nadir;
    if (!quiet) group.append(svg("text", { x: mark.u + r * 1.4, y: mark.v - r * 1.4, "font-size": fontPx }, [text]));
    layer.append(group);
  });
  return layer;
}

/** The image circle of POST /v1/calibrations/image-circle ({center_px, radius_px}, frame px) and a
 *  cross at its centre. */
function circleLayer(circle, fontPx) {
  const [u0, v0] = circle.center_px;
  const s = fontPx * 0.8;
  return svg("g", { class: "image-circle", "data-u": u0, "data-v": v0, "data-r": circle.radius_px }, [
    svg("circle", { class: "image-circle-rim", cx: u0, cy: v0, r: circle.radius_px }),
    svg("path", { class: "image-circle-centre", d: `M ${u0 - s} ${v0} H ${u0 + s} M ${u0} ${v0 - s} V ${v0 + s}` }),
  ]);
}

function checksLayer(checks, fontPx) {
  const layer = svg("g", { class: "checks" });
  for (const check of checks) {
    layer.append(svg("circle", { class: "check", cx: check.u, cy: check.v, r: fontPx * 0.35 }));
    const text = check.xy ? `(${fmt(check.xy[0], 2)}, ${fmt(check.xy[1], 2)}) m · ${fmt(Math.hypot(...check.xy), 2)} m`
      : "no floor point";
    layer.append(svg("text", { class: "check-label", x: check.u + fontPx * 0.6, y: check.v + fontPx * 0.4, "font-size": fontPx }, [text]));
  }
  return layer;
}

/**
 * The overlay <g> for the frame: `camera` (scaled to the frame, or null) gives the rings and tape
 * directions; marks [{id, ruler, u, v, distance_m, x_m, y_m}], residuals Map id -> {err_m, err_px},
 * masks [[[u, v], ...]], drawing (a mask in progress), checks [{u, v, xy}], the image circle
 * ({center_px, radius_px} or null), all in frame pixels;
 * `screenPerFrame` sets the text size.
 */
export function calibrateOverlay({ camera, frameWh, showRings, marks, residuals, selected, masks, drawing, checks,
                                   circle = null, screenPerFrame }) {
  const fontPx = 13 / screenPerFrame;
  const overlay = svg("g", { class: "overlay" });
  if (camera && showRings) {
    try {
      overlay.append(calibrationLayer(camera, frameWh, fontPx));
      overlay.append(tapeLayer(camera, marks, fontPx));
    } catch (error) {
      overlay.append(svg("text", { class: "frame-error", x: 0, y: fontPx * 1.5, "font-size": fontPx }, [error.message]));
    }
  }
  if (circle) overlay.append(circleLayer(circle, fontPx));
  overlay.append(masksLayer(masks, drawing, fontPx));
  overlay.append(marksLayer(marks, residuals, selected, fontPx, screenPerFrame));
  overlay.append(checksLayer(checks, fontPx));
  return overlay;
}
