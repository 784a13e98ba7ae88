// The REST API of the service that serves this page (same origin).

export class ApiError extends Error {
  constructor(status, code, message) {
    super(message);
    this.status = status;
    this.code = code;
  }
}

async function failure(response) {
  let code = "http_error";
  let message = `${response.status} ${response.statusText}`;
  try {
    const body = await response.json();
    if (body && body.error) ({ code, message } = body.error);
  } catch {
    // not the JSON error shape: keep the status line
  }
  return new ApiError(response.status, code, message);
}

async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  if (!response.ok) throw await failure(response);
  return response.json();
}

async function sendJson(method, path, body, token = "") {
  const headers = { "Content-Type": "application/json" };
  if (token) headers.Authorization = `Bearer ${token}`;
  const response = await fetch(path, { method, headers, body: JSON.stringify(body), cache: "no-store" });
  if (!response.ok) throw await failure(response);
  return response.json();
}

const cameraPath = (id) => `/v1/cameras/${encodeURIComponent(id)}`;

export const api = {
  model: () => getJson("/v1/model"),
  cameras: async () => (await getJson("/v1/cameras")).cameras,
  camera: (id) => getJson(cameraPath(id)),

  /** Create or replace a camera record; `token` for a service whose writes need one. */
  putCamera: (id, record, token = "") => sendJson("PUT", cameraPath(id), record, token),

  /** Fit a camera from ruler marks without saving it (POST /v1/calibrations/fit). */
  fitCalibration: (body, token = "") => sendJson("POST", "/v1/calibrations/fit", body, token),

  /** The image circle of an encoded frame (a Blob) and a starting camera from it, nothing saved
   *  (POST /v1/calibrations/image-circle); `altitudeM` null keeps the service's default. */
  async fitImageCircle(blob, cameraId, altitudeM = null) {
    const query = new URLSearchParams({ camera_id: cameraId });
    if (altitudeM !== null) query.set("altitude_m", String(altitudeM));
    const response = await fetch(`/v1/calibrations/image-circle?${query}`, {
      method: "POST", headers: { "Content-Type": blob.type || "image/jpeg" }, body: blob, cache: "no-store",
    });
    if (!response.ok) throw await failure(response);
    return response.json();
  },

  /** The latest frame's record of a camera, or null when it has had none. */
  async latest(cameraId) {
    try {
      return await getJson(`${cameraPath(cameraId)}/latest`);
    } catch (error) {
      if (error instanceof ApiError && error.status === 404 && error.code === "no_frame") return null;
      throw error;
    }
  },

  /** The JPEG of frame `sequence` as a Blob, or null when a newer frame has replaced it. */
  async latestJpeg(cameraId, sequence) {
    const response = await fetch(`${cameraPath(cameraId)}/latest.jpg?sequence=${sequence}`, { cache: "no-store" });
    if (response.status === 409) return null;
    if (!response.ok) throw await failure(response);
    return response.blob();
  },

  /** POST an encoded frame (File/Blob) to the detect route; the detect answer. */
  async detect(cameraId, file, { minScore = null, frameId = null } = {}) {
    const query = new URLSearchParams();
    if (minScore !== null) query.set("min_score", String(minScore));
    if (frameId !== null) query.set("frame_id", frameId);
    const type = file.type === "image/png" ? "image/png" : "image/jpeg";
    const response = await fetch(`${cameraPath(cameraId)}/detect?${query}`, {
      method: "POST", body: file, headers: { "Content-Type": type },
    });
    if (!response.ok) throw await failure(response);
    return response.json();
  },
};
