// The FishLoc viewer: camera list, a camera's frame with detections beside its floor map, and the
// site map of every camera with a site pose, and a camera's Calibrate mode (calibrate.js). Routes:
// #/camera/<id>, #/calibrate/<id> and #/site.
//
// window.fishlocViewer exposes the shown state and the projection for tests and for the console.

import { api } from "./api.js";
import { calibrateState, closeCalibrate, openCalibrate } from "./calibrate.js";
import { fmt, fmtPair, html } from "./dom.js";
import { drawMap, squareBounds } from "./floor_map.js";
import { drawFrame } from "./frame_view.js";
import { floorToPixels, floorToSite, fovRadiusM, pixelsToFloor } from "./geometry.js";

const POLL_MS = 1000;
const $ = (id) => document.getElementById(id);

const state = {
  cameras: [],
  view: null,          // {kind: "camera", id} | {kind: "site"}
  shown: null,         // {cameraId, source: "upload" | "latest", sequence, result, frameUrl}
  site: null,          // {cameras: [...ids], latest: {id: record}}
  uploads: 0,
  renders: 0,
};

function setStatus(message, isError = false) {
  $("status").textContent = message;
  $("status").classList.toggle("error", isError);
}

function cameraById(id) {
  return state.cameras.find((camera) => camera.id === id) ?? null;
}

// ----- people table

function personRow(cameraId, det, index) {
  return html("tr", {
    "data-camera": cameraId, "data-index": index, "data-score": det.score,
    "data-x": det.position_m ? det.position_m[0] : null, "data-y": det.position_m ? det.position_m[1] : null,
  }, [
    html("td", { text: cameraId }), html("td", { text: index + 1 }), html("td", { text: fmt(det.score, 2) }),
    html("td", { text: fmtPair(det.foot_px, 1) }), html("td", { class: "position", text: fmtPair(det.position_m, 2) }),
    html("td", { text: fmt(det.distance_m, 2) }), html("td", { text: fmtPair(det.site_position_m, 2) }),
  ]);
}

function fillTable(rows) {
  $("people").querySelector("tbody").replaceChildren(...rows);
}

// ----- one camera

function cameraMapBounds(camera, detections) {
  const choice = $("map-extent").value;
  const fov = fovRadiusM(camera);
  if (choice === "fov") return squareBounds(0, 0, fov);
  if (choice !== "auto") return squareBounds(0, 0, Number(choice));
  const far = Math.max(0, ...detections.filter((d) => d.position_m).map((d) => Math.max(...d.position_m.map(Math.abs))));
  return squareBounds(0, 0, Math.min(fov, Math.max(4, Math.ceil(far * 1.25 + 0.5))));
}

function renderCamera() {
  const shown = state.shown;
  const camera = cameraById(state.view.id);
  if (!camera) return;
  const detections = shown ? shown.result.detections : [];
  drawMap($("floor-map"), {
    cameras: [{ camera, origin: [0, 0], yawDeg: 0, showRings: true }],
    people: detections.filter((d) => d.position_m).map((d) => ({
      xy: d.position_m, label: `#${detections.indexOf(d) + 1}`, cameraId: camera.id, index: detections.indexOf(d),
    })),
    bounds: cameraMapBounds(camera, detections),
  });
  if (!shown) {
    $("frame").replaceChildren();
    $("frame-info").textContent = "No frame yet: upload one, or send frames over REST or gRPC and press Latest frame.";
    fillTable([]);
    return;
  }
  drawFrame($("frame"), { frameUrl: shown.frameUrl, result: shown.result, camera, showRings: $("rings").checked });
  const r = shown.result;
  const where = shown.source === "upload" ? "uploaded" : `latest frame #${shown.sequence} (${shown.frontend}, ${shown.receivedAt})`;
  $("frame-info").textContent = `${where}: ${r.image.width}×${r.image.height} px, ${r.detections.length} ` +
    `people, model ${r.model.name} ${r.model.version}, ${fmt(r.timing_ms.total, 1)} ms` +
    (r.frame_id ? `, frame_id ${r.frame_id}` : "");
  fillTable(r.detections.map((det, i) => personRow(camera.id, det, i)));
  state.renders += 1;
  document.body.dataset.shown = `${camera.id}:${shown.source}:${shown.sequence ?? shown.upload}`;
}

async function imageUrl(blob) {
  const url = URL.createObjectURL(blob);
  const image = new Image();
  image.src = url;
  await image.decode(); // draw the overlay once the frame can be painted under it
  return url;
}

function show(shown) {
  if (state.shown && state.shown.frameUrl !== shown.frameUrl) URL.revokeObjectURL(state.shown.frameUrl);
  state.shown = shown;
  renderCamera();
}

async function showLatest(cameraId, { quiet = false } = {}) {
  const record = await api.latest(cameraId);
  if (state.view?.kind !== "camera" || state.view.id !== cameraId) return;
  if (record === null) {
    if (!quiet) setStatus(`camera ${cameraId} has had no frame since the service started`);
    return;
  }
  if (state.shown && state.shown.source === "latest" && state.shown.sequence === record.sequence) return;
  const blob = await api.latestJpeg(cameraId, record.sequence);
  if (blob === null) return showLatest(cameraId, { quiet }); // replaced meanwhile: take the newer one
  const frameUrl = await imageUrl(blob);
  if (state.view?.kind !== "camera" || state.view.id !== cameraId) return URL.revokeObjectURL(frameUrl);
  show({ cameraId, source: "latest", sequence: record.sequence, frontend: record.frontend,
         receivedAt: record.received_at, result: record.result, frameUrl });
  if (!quiet) setStatus(`showing frame #${record.sequence}`);
}

async function upload(file) {
  const cameraId = state.view.id;
  const text = $("min-score").value.trim();
  setStatus(`detecting people in ${file.name}…`);
  const result = await api.detect(cameraId, file, { minScore: text === "" ? null : Number(text), frameId: file.name });
  const frameUrl = await imageUrl(file);
  state.uploads += 1;
  show({ cameraId, source: "upload", upload: state.uploads, sequence: null, result, frameUrl });
  setStatus(`${file.name}: ${result.detections.length} people`);
}

async function openCamera(id) {
  const camera = cameraById(id);
  $("camera-view").hidden = false;
  $("site-view").hidden = true;
  if (!camera) {
    $("camera-title").textContent = id;
    setStatus(`no camera ${id} in the registry`, true);
    return;
  }
  $("camera-title").textContent = `${camera.id} · ${fmt(camera.altitude_m, 2)} m`;
  $("calibrate-link").href = `#/calibrate/${encodeURIComponent(camera.id)}`;
  if (state.shown?.cameraId !== id) {
    if (state.shown) URL.revokeObjectURL(state.shown.frameUrl);
    state.shown = null;
  }
  renderCamera();
  await showLatest(id, { quiet: true });
}

// ----- site map

/** The site map's extent: around the cameras and people, or around every field of view. */
function siteBounds(posed, people) {
  const boxes = posed.map((camera) => {
    const reach = $("site-extent").value === "fov" ? fovRadiusM(camera) : 4;
    const { x_m: x, y_m: y } = camera.site_pose;
    return [x - reach, x + reach, y - reach, y + reach];
  });
  for (const { xy: [x, y] } of people) boxes.push([x - 2, x + 2, y - 2, y + 2]);
  if (!boxes.length) return squareBounds(0, 0, 6);
  const [xmin, xmax, ymin, ymax] = [0, 1, 2, 3].map((k) => (k % 2 === 0 ? Math.min : Math.max)(...boxes.map((b) => b[k])));
  return { xmin, xmax, ymin, ymax };
}

async function renderSite() {
  const posed = state.cameras.filter((camera) => camera.site_pose);
  const records = await Promise.all(posed.map((camera) => api.latest(camera.id).catch(() => null)));
  if (state.view?.kind !== "site") return;
  const people = [];
  const rows = [];
  posed.forEach((camera, c) => {
    const record = records[c];
    if (!record) return;
    record.result.detections.forEach((det, index) => {
      rows.push(personRow(camera.id, det, index));
      const xy = det.site_position_m ?? (det.position_m && floorToSite(camera, ...det.position_m));
      if (xy) people.push({ xy, label: `${camera.id} #${index + 1}`, cameraId: camera.id, index });
    });
  });
  drawMap($("site-map"), {
    cameras: posed.map((camera) => ({
      camera, origin: [camera.site_pose.x_m, camera.site_pose.y_m], yawDeg: camera.site_pose.yaw_deg, showRings: false,
    })),
    people,
    bounds: siteBounds(posed, people),
  });
  fillTable(rows);
  const withFrames = records.filter(Boolean).map((r) => r.sequence);
  $("site-info").textContent = `cameras with a site pose: ${posed.length}, people: ${people.length} (latest frame of each camera)` + (posed.length < state.cameras.length
      ? `; not on it (no site pose): ${state.cameras.filter((c) => !c.site_pose).map((c) => c.id).join(", ")}` : "");
  state.site = { cameras: posed.map((c) => c.id), sequences: withFrames, people: people.length };
  state.renders += 1;
  document.body.dataset.shown = `site:${withFrames.join(",")}`;
}

async function openSite() {
  $("camera-view").hidden = true;
  $("site-view").hidden = false;
  await renderSite();
}

// ----- navigation

function renderCameraList() {
  const active = ["camera", "calibrate"].includes(state.view?.kind) ? state.view.id : null;
  $("camera-list").replaceChildren(...state.cameras.map((camera) => html("li", {}, [
    html("a", { href: `#/camera/${encodeURIComponent(camera.id)}`, class: camera.id === active ? "active" : null,
                "data-camera": camera.id }, [camera.id, html("small", { text: camera.site_pose ? "site" : "" })]),
  ])));
  $("site-link").classList.toggle("active", state.view?.kind === "site");
}

function parseHash() {
  const hash = decodeURIComponent(location.hash.replace(/^#\/?/, ""));
  if (hash === "site") return { kind: "site" };
  if (hash.startsWith("camera/")) return { kind: "camera", id: hash.slice("camera/".length) };
  if (hash.startsWith("calibrate/")) return { kind: "calibrate", id: hash.slice("calibrate/".length) };
  return state.cameras.length ? { kind: "camera", id: state.cameras[0].id } : { kind: "none" };
}

async function route() {
  state.cameras = await api.cameras();
  state.view = parseHash();
  renderCameraList();
  setStatus("");
  const calibrating = state.view.kind === "calibrate";
  if (!calibrating) closeCalibrate();
  $("people").hidden = calibrating;
  if (calibrating) {
    $("camera-view").hidden = true;
    $("site-view").hidden = true;
    await openCalibrate(state.view.id, state.cameras, setStatus);
  } else if (state.view.kind === "camera") await openCamera(state.view.id);
  else if (state.view.kind === "site") await openSite();
  else setStatus("the registry has no cameras: add one with PUT /v1/cameras/{id}");
}

function guarded(action) {
  return (...args) => Promise.resolve(action(...args)).catch((error) => setStatus(error.message, true));
}

let polling = false;

async function poll() {
  if (polling) return; // the previous poll is still waiting for the service
  polling = true;
  try {
    await pollOnce();
  } finally {
    polling = false;
  }
}

async function pollOnce() {
  if (state.view?.kind === "camera" && $("follow").checked) await showLatest(state.view.id, { quiet: true });
  if (state.view?.kind === "site" && $("site-follow").checked) await renderSite();
}

async function main() {
  window.addEventListener("hashchange", guarded(route));
  $("upload").addEventListener("change", guarded(async (event) => {
    const [file] = event.target.files;
    event.target.value = "";
    if (file) await upload(file);
  }));
  $("show-latest").addEventListener("click", guarded(() => showLatest(state.view.id)));
  for (const id of ["rings", "map-extent"]) $(id).addEventListener("change", () => renderCamera());
  $("site-extent").addEventListener("change", guarded(renderSite));
  const tick = guarded(poll);
  setInterval(tick, POLL_MS);
  try {
    const model = await api.model();
    $("model").textContent = `model ${model.name} ${model.version} · input ${model.input_size} px`;
  } catch (error) {
    $("model").textContent = `model: ${error.message}`;
  }
  await guarded(route)();
  document.body.dataset.state = "ready";
}

window.fishlocViewer = { state, calibrate: calibrateState, floorToPixels, pixelsToFloor, fovRadiusM };
main();
