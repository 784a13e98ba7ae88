// What the Calibrate mode reads and writes, as pure functions: marks.csv at the camera's image size
// (the page keeps marks in frame pixels), and the camera record that Save puts in the registry.

import { marksToCsv, parseMarksCsv } from "./marks_csv.js";
import { rescalePoints } from "./masks.js";

/** The marks.csv text of marks in pixels of a `frameWh` frame, written at `imageWh`. */
export function marksCsvAt(marks, frameWh, imageWh) {
  const uv = rescalePoints(marks.map((m) => [m.u, m.v]), frameWh, imageWh);
  return marksToCsv(marks.map((m, i) => ({ ...m, u: uv[i][0], v: uv[i][1] })));
}

/** Marks of a marks.csv at `imageWh`, in pixels of a `frameWh` frame, with ids from `firstId`. */
export function marksFromCsv(text, source, imageWh, frameWh, firstId) {
  const marks = parseMarksCsv(text, source);
  const uv = rescalePoints(marks.map((m) => [m.u, m.v]), imageWh, frameWh);
  return marks.map((m, i) => ({ ...m, id: firstId + i, u: uv[i][0], v: uv[i][1] }));
}

/**
 * The record Save writes: the fitted lens (or, with no marks, the saved one, else `start`: the
 * starting camera of the frame's image circle), the saved camera's
 * `site`, `site_pose`, `second_look_pixels` and `longest_person_ratio` (what the calibration does not
 * decide), and `masks`
 * (frame px of a `frameWh` frame; null keeps the saved ones).
 * Throws an Error when the marks give no camera to save.
 */
export function cameraRecord({ cameraId, saved, start = null, marks, fit, fitError, masks, frameWh }) {
  if (marks.length && !fit) {
    throw new Error(`the marks give no calibration yet (${fitError ?? "fitting"}); fix them, or delete them to ` +
                    "save the masks alone");
  }
  const lens = fit ? fit.camera : (saved ?? start);
  if (!lens) throw new Error(`camera ${cameraId} is not in the registry and has no fit: click marks, or fit the image circle`);
  const kept = ["site", "site_pose", "second_look_pixels", "longest_person_ratio"];
  const place = Object.fromEntries(kept.filter((k) => saved?.[k] != null).map((k) => [k, saved[k]]));
  const masksPx = masks === null ? (saved?.masks_px ?? []) : masks.map((points) => rescalePoints(points, frameWh, lens.image_size));
  return { ...lens, ...place, id: cameraId, masks_px: masksPx };
}

/** `record` with the view budget typed in the page (`text`: px, or empty for the server's). */
export function withViewBudget(record, text) {
  const { max_view_pixels: _, ...rest } = record;
  if (String(text).trim() === "") return rest;
  const pixels = Number(text);
  if (!Number.isInteger(pixels) || pixels < 4096) throw new Error(`the view budget must be a whole number of px, at least 4096 (or empty): got ${text}`);
  return { ...rest, max_view_pixels: pixels };
}

/** One line of a camera's planned view (`GET /v1/cameras/{id}`'s `view`; "" for a fixed view). */
export function describeView(view) {
  if (!view) return "";
  const px = (n) => n.toLocaleString("en-US");
  const whose = view.budget?.source === "camera" ? "this camera's" : "the server's";
  const budget = view.budget ? ` of ${whose} ${px(view.budget.max_pixels)}` : "";
  const wanted = view.wanted_pixels > view.pixels ? `; its people ask for ${px(view.wanted_pixels)} px` : "";
  return `view: ${view.layout}, ${px(view.pixels)} px${budget}${wanted}`;
}
