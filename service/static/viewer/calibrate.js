// The Calibrate mode of one camera (#/calibrate/<id>): on its latest or an uploaded frame, click the
// nadir and marks along tapes laid on the floor, see the fit of POST /v1/calibrations/fit after every
// change (residual of each mark, fitted rings and tape directions, RMS, the fitter's notes), draw
// masks, and save the camera with PUT /v1/cameras/{id}: nothing is written before Save. The Check
// tool then gives the floor position of any clicked pixel by the saved calibration.
//
// Fit image circle (POST /v1/calibrations/image-circle) draws the frame's image circle and its
// centre; for a camera not calibrated yet, that centre is the fit's starting principal point while
// no nadir is clicked, and the circle's 180° equidistant lens the starting lens (drawn, and saved
// when there are no marks).
//
// Marks and masks are kept in frame pixels; the fit is sent them with the frame's size, while
// marks.csv and `masks_px` are at the image size (u' = (u + 0.5)·s − 0.5 when the frame has another
// resolution of the same aspect ratio).

import { api } from "./api.js";
import { cameraRecord, describeView, marksCsvAt, marksFromCsv, withViewBudget } from "./calibrate_io.js";
import { calibrateOverlay } from "./calibrate_overlay.js";
import { renderPanel } from "./calibrate_panel.js";
import { fmt, html, svg } from "./dom.js";
import { pixelToFloorPoint, scaledCamera } from "./geometry.js";
import { withEdit, withNadir } from "./mark_edits.js";
import { rescalePoints } from "./masks.js";
import { attachZoomPan } from "./zoom_pan.js";

const $ = (id) => document.getElementById(id);
const CLOSE_MASK_PX = 10; // a click this near (screen px) the first corner closes the mask
const MAX_CHECKS = 8;

const HINTS = {
  nadir: "Click the point straight below the lens (the tapes' zero); click again to move it.",
  mark: "Click a mark on a tape: it gets the ruler and distance of 'Next mark', then the distance moves on by the step. " +
        "Drag a mark to move it, click one to select it (Delete removes it), edit it in the table.",
  mask: "Click the corners of a mirror, poster, screen or window; click the first corner or press Enter to close it, " +
        "Escape to drop it.",
  check: "Click a floor point: its position and distance from the nadir by the saved calibration.",
};

export const calibrateState = {
  cameraId: null,
  camera: null,        // the saved record
  frame: null,         // {url, blob, width, height, source}
  circle: null,        // the image-circle answer for the shown frame (frame px)
  start: null,         // the starting camera from it, for a camera with no calibration yet
  circles: 0,          // image circles fitted
  marks: [],           // [{id, ruler, u, v, distance_m, x_m, y_m}] frame px
  masks: [],           // [[[u, v], ...]] frame px
  drawing: [],         // the mask being drawn
  checks: [],          // [{u, v, xy}]
  selected: null,      // id of the selected mark
  nextId: 1,
  fit: null,           // the fit answer
  fitIds: [],          // ids of the marks that fit was made from, in order
  fitError: null,
  fitsWanted: 0,
  fitsDone: 0,
  fitting: false,
  unsaved: false,
  frames: 0,           // frames loaded
  saves: 0,
  renders: 0,
};
const cal = calibrateState;
let zoom = null;
let report = () => {};

// ----- sizes

function frameWh() {
  return [cal.frame.width, cal.frame.height];
}

/** The image size of the fit as entered, or an Error saying what is wrong with it. */
function imageWh() {
  const size = [Number($("cal-width").value), Number($("cal-height").value)];
  if (!size.every((n) => Number.isInteger(n) && n >= 2)) return new Error("enter the image size (whole pixels, 2 or more)");
  return size;
}

/** `size` when the frame's pixels scale to it (same aspect ratio, as the service allows), else an Error. */
function scalableTo(size) {
  if (size instanceof Error) return size;
  if (Math.abs(size[0] * cal.frame.height - size[1] * cal.frame.width) > Math.max(...size)) {
    return new Error(`the frame is ${cal.frame.width}×${cal.frame.height} px but the image size is ${size[0]}×${size[1]} px, ` +
                     "another aspect ratio: take a frame of this camera or enter its size");
  }
  return size;
}

// ----- fitting

function fitRequest() {
  if (!cal.frame) return new Error("no frame yet: press Latest frame or upload one");
  if (!cal.marks.length) return new Error("no marks yet: click the nadir, then marks along a tape");
  const size = imageWh();
  if (size instanceof Error) return size;
  const altitude = Number($("cal-altitude").value);
  if (!(altitude > 0)) return new Error("enter the altitude of the lens above the floor (m, > 0)");
  // Marks go in frame pixels with the frame's size: the service scales them to the image size.
  return {
    camera_id: cal.cameraId,
    altitude_m: altitude,
    image_size: size,
    frame_size: frameWh(),
    marks: cal.marks.map((m) => ({
      ruler: m.ruler, u: m.u, v: m.v, distance_m: m.distance_m, ...(m.x_m !== null ? { x_m: m.x_m, y_m: m.y_m } : {}),
    })),
    options: {
      ...startingPrincipalPoint(size),
      coefficients: Number($("cal-coefficients").value),
      fit_principal_point: $("cal-fit-pp").checked,
      fit_tilt: $("cal-fit-tilt").checked,
    },
  };
}

/** `{principal_point}` at image size `size` from the image circle while the camera has no calibration
 *  and no nadir is clicked; `{}` otherwise (the nadir mark gives it). */
function startingPrincipalPoint(size) {
  if (!cal.start || !cal.circle || cal.marks.some((m) => m.distance_m === 0)) return {};
  const [point] = rescalePoints([cal.circle.circle.center_px], frameWh(), size);
  return { principal_point: point };
}

async function fitOnce() {
  const body = fitRequest();
  const ids = cal.marks.map((m) => m.id);
  if (body instanceof Error) {
    Object.assign(cal, { fit: null, fitIds: [], fitError: body.message });
    return;
  }
  try {
    const answer = await api.fitCalibration(body, $("cal-token").value.trim());
    Object.assign(cal, { fit: answer, fitIds: ids, fitError: null });
  } catch (error) {
    Object.assign(cal, { fit: null, fitIds: [], fitError: error.message });
  }
}

/** Fit again after a change (`changed`: to what Save would write); one request at a time, the
 *  last change always fitted. */
async function refit({ changed = true } = {}) {
  cal.fitsWanted += 1;
  cal.unsaved ||= changed;
  render();
  if (cal.fitting) return;
  cal.fitting = true;
  try {
    while (cal.fitsDone < cal.fitsWanted) {
      const wanted = cal.fitsWanted;
      await fitOnce();
      cal.fitsDone = wanted;
    }
  } finally {
    cal.fitting = false;
  }
  render();
}

function residuals() {
  const byId = new Map();
  if (cal.fit) cal.fitIds.forEach((id, i) => byId.set(id, cal.fit.marks[i]));
  return byId;
}

/** The camera drawn over the frame: the fit, else the saved calibration; scaled to the frame. */
function shownCamera() {
  const camera = cal.fit ? cal.fit.camera : (cal.camera ?? cal.start);
  try {
    return camera && cal.frame ? scaledCamera(camera, frameWh()) : null;
  } catch {
    return null;
  }
}

// ----- drawing

function renderFrame() {
  const root = $("cal-frame");
  const overlay = root.querySelector("g.overlay");
  if (!cal.frame) {
    root.replaceChildren();
    return;
  }
  const next = calibrateOverlay({
    camera: shownCamera(), frameWh: frameWh(), showRings: $("cal-rings").checked, marks: cal.marks,
    residuals: residuals(), selected: cal.selected, masks: cal.masks, drawing: cal.drawing, checks: cal.checks,
    circle: cal.circle?.circle ?? null, screenPerFrame: zoom.view().screenPerFrame,
  });
  if (overlay) overlay.replaceWith(next);
  else root.append(next);
}

function render() {
  renderFrame();
  const size = imageWh();
  const scaledTo = cal.frame && !(size instanceof Error) && (size[0] !== cal.frame.width || size[1] !== cal.frame.height)
    ? size : null;
  renderPanel(cal, residuals(), scaledTo);
  cal.renders += 1;
  document.body.dataset.calibrate = `${cal.cameraId}:${cal.fitsDone}/${cal.fitsWanted}${cal.fitting ? ":fitting" : ""}`;
  document.body.dataset.circles = String(cal.circles);
}

// ----- frames

async function loadFrame(blob, source) {
  const url = URL.createObjectURL(blob);
  const image = new Image();
  image.src = url;
  await image.decode();
  const [width, height] = [image.naturalWidth, image.naturalHeight];
  const old = cal.frame;
  if (old) URL.revokeObjectURL(old.url);
  // Marks and masks stay on the floor they were put on: carried to the new frame's pixels.
  const carry = (points) => (old ? rescalePoints(points, [old.width, old.height], [width, height]) : points);
  cal.marks = cal.marks.map((m) => {
    const [[u, v]] = carry([[m.u, m.v]]);
    return { ...m, u, v };
  });
  cal.masks = old ? cal.masks.map(carry) : savedMasks([width, height]);
  cal.frame = { url, blob, width, height, source };
  cal.circle = null; // fitted on the frame it was drawn over
  cal.frames += 1;
  if ($("cal-width").value === "" && $("cal-height").value === "") { // a new camera: calibrate at the frame's size
    $("cal-width").value = String(width);
    $("cal-height").value = String(height);
  }
  cal.checks = [];
  const root = $("cal-frame");
  root.replaceChildren(svg("image", { href: url, x: -0.5, y: -0.5, width, height, preserveAspectRatio: "none" }));
  zoom.setFrame(width, height);
  await refit({ changed: false });
}

/** The saved camera's masks in pixels of a frame `wh` ([] when it has none or another aspect ratio). */
function savedMasks(wh) {
  const masks = cal.camera?.masks_px ?? [];
  const [w, h] = cal.camera?.image_size ?? wh;
  if (Math.abs(w * wh[1] - h * wh[0]) > Math.max(w, h)) return [];
  return masks.map((points) => rescalePoints(points, [w, h], wh));
}

async function loadLatest() {
  const record = await api.latest(cal.cameraId);
  if (record === null) throw new Error(`camera ${cal.cameraId} has had no frame since the service started: upload one`);
  const blob = await api.latestJpeg(cal.cameraId, record.sequence);
  if (blob === null) return loadLatest();
  await loadFrame(blob, `latest frame #${record.sequence}`);
  return record.sequence;
}

async function fitCircle() {
  if (!cal.frame) throw new Error("no frame yet: press Latest frame or upload one");
  const altitude = Number($("cal-altitude").value);
  const answer = await api.fitImageCircle(cal.frame.blob, cal.cameraId, altitude > 0 ? altitude : null);
  cal.circle = answer;
  cal.circles += 1;
  const { center_px: [u0, v0], radius_px: radius, cut } = answer.circle;
  const sides = ["top", "bottom", "left", "right"].filter((side) => cut[side]);
  let use = "the saved calibration stays the lens";
  if (!cal.camera) { // nobody calibrated this camera: the circle's lens is where it starts
    cal.start = answer.camera;
    if (!(altitude > 0)) $("cal-altitude").value = String(answer.camera.altitude_m);
    use = "its centre is the starting principal point and its 180° lens the starting lens";
  }
  report(`image circle: centre (${fmt(u0, 1)}, ${fmt(v0, 1)}) px, radius ${fmt(radius, 1)} px` +
         (sides.length ? `, cut by the frame at its ${sides.join(", ")}` : "") + `; ${use}`);
  await refit({ changed: !cal.camera });
}

// ----- editing

function addMark(u, v) {
  const distance = Number($("cal-distance").value);
  if (!(distance > 0)) throw new Error("enter the distance of the next mark (m, > 0); the nadir tool sets distance 0");
  const mark = { id: cal.nextId++, ruler: $("cal-ruler").value.trim(), u, v, distance_m: distance, x_m: null, y_m: null };
  cal.marks = [...cal.marks, mark];
  cal.selected = mark.id;
  const step = Number($("cal-step").value);
  if (step > 0) $("cal-distance").value = String(+(distance + step).toFixed(6));
  return refit();
}

function setNadir(u, v) {
  const nadir = cal.marks.find((m) => m.distance_m === 0);
  cal.selected = nadir ? nadir.id : cal.nextId++;
  cal.marks = withNadir(cal.marks, u, v, cal.selected);
  return refit();
}

function deleteMark(id) {
  cal.marks = cal.marks.filter((m) => m.id !== Number(id));
  if (cal.selected === Number(id)) cal.selected = null;
  return refit();
}

function editMark(id, field, text) {
  try {
    cal.marks = withEdit(cal.marks, Number(id), field, text);
  } catch (error) {
    render(); // the table shows the value it kept
    throw error;
  }
  return refit();
}

function moveMark(id, u, v) {
  cal.marks = cal.marks.map((m) => (m.id === id ? { ...m, u, v } : m));
}

function closeMask() {
  if (cal.drawing.length < 3) throw new Error("a mask needs 3 or more corners");
  cal.masks.push(cal.drawing);
  cal.drawing = [];
  cal.unsaved = true;
  render();
}

function addMaskCorner(u, v) {
  const first = cal.drawing[0];
  if (first && cal.drawing.length >= 3) {
    const [a, b] = [zoom.toClient(...first), zoom.toClient(u, v)];
    if (Math.hypot(a[0] - b[0], a[1] - b[1]) <= CLOSE_MASK_PX) return closeMask();
  }
  cal.drawing.push([u, v]);
  render();
}

function check(u, v) {
  if (!cal.camera) throw new Error(`camera ${cal.cameraId} is not in the registry`);
  const xy = pixelToFloorPoint(scaledCamera(cal.camera, frameWh()), u, v);
  cal.checks = [...cal.checks, { u, v, xy }].slice(-MAX_CHECKS);
  $("cal-check").textContent = xy
    ? `pixel (${fmt(u, 1)}, ${fmt(v, 1)}): floor (${fmt(xy[0], 3)}, ${fmt(xy[1], 3)}) m, ` +
      `${fmt(Math.hypot(...xy), 3)} m from the nadir (saved calibration)`
    : `pixel (${fmt(u, 1)}, ${fmt(v, 1)}) has no floor point (beyond the calibrated field or the horizon)`;
  $("cal-check").dataset.xy = xy ? JSON.stringify(xy) : "null";
  render();
}

function tool() {
  return document.querySelector('input[name="cal-tool"]:checked').value;
}

function onFrameClick(u, v, element) {
  if (!cal.frame) return;
  const mode = tool();
  if (mode === "mask") return addMaskCorner(u, v);
  if (mode === "check") return check(u, v);
  if (element?.dataset.markId) { // a click on a mark selects it
    cal.selected = Number(element.dataset.markId);
    return render();
  }
  return mode === "nadir" ? setNadir(u, v) : addMark(u, v);
}

// ----- import, export, save

async function importCsv(file) {
  if (!cal.frame) throw new Error("load the frame the marks were taken on first");
  const size = scalableTo(imageWh());
  if (size instanceof Error) throw size;
  const marks = marksFromCsv(await file.text(), file.name, size, frameWh(), cal.nextId);
  Object.assign(cal, { marks, nextId: cal.nextId + marks.length, selected: null });
  report(`${file.name}: ${marks.length} marks`);
  await refit();
}

function download() {
  if (!cal.frame) throw new Error("no marks to export: load a frame and click some");
  const size = scalableTo(imageWh());
  if (size instanceof Error) throw size;
  const text = marksCsvAt(cal.marks, frameWh(), size);
  const link = html("a", { href: URL.createObjectURL(new Blob([text], { type: "text/csv" })), download: `${cal.cameraId}-marks.csv` });
  cal.exported = text;
  link.click();
  setTimeout(() => URL.revokeObjectURL(link.href), 0);
}

async function save() {
  if (cal.drawing.length) throw new Error("close or drop the mask being drawn first (Enter or Escape)");
  if (cal.fitting || cal.fitsDone < cal.fitsWanted) throw new Error("the fit is not finished yet");
  const lensWh = (cal.fit?.camera ?? cal.camera)?.image_size;
  if (cal.frame && lensWh && scalableTo(lensWh) instanceof Error) throw scalableTo(lensWh); // masks could not follow
  const record = withViewBudget(
    cameraRecord({ cameraId: cal.cameraId, saved: cal.camera, start: cal.start, marks: cal.marks, fit: cal.fit,
                   fitError: cal.fitError, masks: cal.frame ? cal.masks : null, frameWh: cal.frame ? frameWh() : null }),
    $("cal-view-pixels").value);
  const saved = await api.putCamera(cal.cameraId, record, $("cal-token").value.trim());
  cal.camera = saved;
  cal.unsaved = false;
  cal.saves += 1;
  report(`saved camera ${saved.id}; the Check tool now uses it`);
  render();
  await showView();
}

/** The service's plan of the camera's view (a planned model), and the budget it was planned within;
 * nothing for a camera not in the registry yet. */
async function showView() {
  const shown = cal.cameraId;
  const text = cal.camera ? describeView((await api.camera(shown)).view) : "";
  if (cal.cameraId === shown) $("cal-view").textContent = text;
}

// ----- wiring

function guarded(action) {
  return (...args) => Promise.resolve().then(() => action(...args)).catch((error) => {
    report(error.message, true);
    render();
  });
}

let wired = false;

function wire() {
  zoom = attachZoomPan($("cal-frame"), {
    click: guarded((u, v, _event, element) => onFrameClick(u, v, element)),
    dragStart: (element) => {
      if (!element.dataset.markId || !["nadir", "mark"].includes(tool())) return false;
      cal.selected = Number(element.dataset.markId);
      return true;
    },
    drag: (u, v) => {
      moveMark(cal.selected, u, v);
      renderFrame();
    },
    dragEnd: guarded((u, v) => {
      moveMark(cal.selected, u, v);
      return refit();
    }),
    view: () => cal.frame && renderFrame(),
  });
  $("cal-upload").addEventListener("change", guarded(async (event) => {
    const [file] = event.target.files;
    event.target.value = "";
    if (file) await loadFrame(file, `uploaded ${file.name}`);
  }));
  $("cal-latest").addEventListener("click", guarded(loadLatest));
  $("cal-circle").addEventListener("click", guarded(fitCircle));
  $("cal-whole").addEventListener("click", () => zoom.whole());
  $("cal-one").addEventListener("click", () => zoom.oneToOne());
  $("cal-rings").addEventListener("change", () => renderFrame());
  for (const id of ["cal-altitude", "cal-width", "cal-height", "cal-coefficients", "cal-fit-pp", "cal-fit-tilt"]) {
    $(id).addEventListener("change", guarded(() => refit()));
  }
  for (const input of document.querySelectorAll('input[name="cal-tool"]')) {
    input.addEventListener("change", () => { $("cal-hint").textContent = HINTS[tool()]; });
  }
  $("cal-marks").addEventListener("change", guarded((event) => {
    const { markId, field } = event.target.dataset;
    if (markId && field) return editMark(markId, field, event.target.value);
  }));
  $("cal-marks").addEventListener("click", guarded((event) => {
    const button = event.target.closest("button.delete");
    if (button) return deleteMark(button.dataset.markId);
    const row = event.target.closest("tr[data-mark-id]");
    if (row && event.target.tagName !== "INPUT") {
      cal.selected = Number(row.dataset.markId);
      render();
    }
  }));
  $("cal-masks").addEventListener("click", guarded((event) => {
    const button = event.target.closest("button.delete");
    if (!button) return;
    cal.masks = cal.masks.filter((_, i) => i !== Number(button.dataset.mask));
    cal.unsaved = true;
    render();
  }));
  $("cal-import").addEventListener("change", guarded(async (event) => {
    const [file] = event.target.files;
    event.target.value = "";
    if (file) await importCsv(file);
  }));
  $("cal-export").addEventListener("click", guarded(download));
  $("cal-save").addEventListener("click", guarded(save));
  $("cal-view-pixels").addEventListener("change", () => {
    cal.unsaved = true;
    render();
  });
  document.addEventListener("keydown", guarded((event) => {
    if ($("calibrate-view").hidden || ["INPUT", "SELECT", "TEXTAREA"].includes(event.target.tagName)) return;
    if (event.key === "Enter" && cal.drawing.length) return closeMask();
    if (event.key === "Escape" && cal.drawing.length) {
      cal.drawing = [];
      return render();
    }
    if ((event.key === "Delete" || event.key === "Backspace") && cal.selected !== null) return deleteMark(cal.selected);
  }));
}

/** Show the Calibrate mode of camera `cameraId` (a record of `cameras`, or none yet). */
export async function openCalibrate(cameraId, cameras, setStatus) {
  report = setStatus;
  if (!wired) {
    wire();
    wired = true;
  }
  $("calibrate-view").hidden = false;
  $("cal-title").textContent = `Calibrate ${cameraId}`;
  $("cal-hint").textContent = HINTS[tool()];
  const camera = cameras.find((c) => c.id === cameraId) ?? null;
  if (cal.cameraId !== cameraId) {
    if (cal.frame) URL.revokeObjectURL(cal.frame.url);
    Object.assign(cal, { cameraId, camera, frame: null, marks: [], masks: [], drawing: [], checks: [], selected: null,
                         fit: null, fitIds: [], fitError: null, unsaved: false, circle: null, start: null });
    $("cal-check").textContent = "";
    $("cal-altitude").value = camera ? String(camera.altitude_m) : "";
    $("cal-width").value = camera ? String(camera.image_size[0]) : "";
    $("cal-height").value = camera ? String(camera.image_size[1]) : "";
    $("cal-fit-tilt").checked = Boolean(camera?.tilt_deg?.some((a) => a !== 0));
    $("cal-view-pixels").value = camera?.max_view_pixels ? String(camera.max_view_pixels) : "";
    $("cal-view").textContent = "";
    $("cal-frame").replaceChildren();
    render();
    await showView().catch((error) => report(`the camera's view: ${error.message}`, true));
    if (!camera) setStatus(`camera ${cameraId} is not in the registry yet: the fit makes a new one`);
    try {
      await loadLatest();
    } catch {
      // no frame yet: the page says so
    }
  } else {
    cal.camera = camera ?? cal.camera;
    render();
  }
}

/** Leave the Calibrate mode (its marks stay for when it is opened again). */
export function closeCalibrate() {
  $("calibrate-view").hidden = true;
}
