// Camera geometry for drawing: the forward projection floor (x, y) m -> frame pixel, as in
// fisheye/camera.py (FisheyeCamera.scaled_to, floor_to_pixels) and DESIGN.md's conventions.
// Pixels: u right, v down, centres at integers. Floor frame: origin at the nadir, x towards image
// right, y towards image top. r(θ) = k1·θ + k2·θ³ + ... (Kannala–Brandt).

export const DEFAULT_MAX_THETA_DEG = 90;
export const FOV_LIMIT_DEG = 85; // beyond this the floor runs off towards the horizon

const deg = Math.PI / 180;

export function thetaMaxDeg(camera) {
  return camera.max_theta_deg ?? DEFAULT_MAX_THETA_DEG;
}

/** r(θ) of the lens polynomial (Horner in θ²), θ in rad -> normalised radius. */
export function thetaToRadius(thetaRad, kb) {
  const t2 = thetaRad * thetaRad;
  let r = 0;
  for (let i = kb.length - 1; i >= 0; i -= 1) r = r * t2 + kb[i];
  return r * thetaRad;
}

/** The camera for frames of `resolutionWh` (same aspect ratio): u' = (u + 0.5)·s − 0.5, f' = f·s. */
export function scaledCamera(camera, resolutionWh) {
  const [width, height] = resolutionWh;
  const [calibW, calibH] = camera.image_size;
  if (width === calibW && height === calibH) return camera;
  if (Math.abs(width * calibH - height * calibW) > Math.max(calibW, calibH)) {
    throw new Error(`frame ${width}x${height} does not have the aspect ratio of camera ` +
                    `${camera.id}'s calibration (${calibW}x${calibH})`);
  }
  const su = width / calibW;
  const sv = height / calibH;
  const [u0, v0] = camera.principal_point;
  const [fx, fy] = camera.focal_px;
  return {
    ...camera,
    image_size: [width, height],
    principal_point: [(u0 + 0.5) * su - 0.5, (v0 + 0.5) * sv - 0.5],
    focal_px: [fx * su, fy * sv],
  };
}

/** One floor point (x, y) m -> [u, v] px of a camera already scaled to the frame; null beyond θmax. */
export function floorPointToPixel(camera, x, y) {
  const d = Math.hypot(x, y);
  const theta = Math.atan2(d, camera.altitude_m);
  if (theta > thetaMaxDeg(camera) * deg + 1e-12) return null;
  const r = thetaToRadius(theta, camera.kb);
  const cosPhi = d > 0 ? x / d : 1;
  const sinPhi = d > 0 ? y / d : 0;
  const [u0, v0] = camera.principal_point;
  const [fx, fy] = camera.focal_px;
  return [u0 + fx * r * cosPhi, v0 - fy * r * sinPhi];
}

/** Floor points [[x, y], ...] m -> [[u, v] | null, ...] px in frames of `resolutionWh`. */
export function floorToPixels(camera, resolutionWh, points) {
  const scaled = scaledCamera(camera, resolutionWh);
  return points.map(([x, y]) => floorPointToPixel(scaled, x, y));
}

/** Radius (m) of the floor the camera sees: where θ reaches min(θmax, 85°). */
export function fovRadiusM(camera) {
  return camera.altitude_m * Math.tan(Math.min(thetaMaxDeg(camera), FOV_LIMIT_DEG) * deg);
}

/** The ring of floor points at `radiusM` around the nadir, as pixel runs (split where a point has
 *  no pixel), `samples` points per turn starting on the +x axis and turning counter-clockwise. */
export function floorRingPixels(scaled, radiusM, samples = 180) {
  const runs = [];
  let run = [];
  for (let i = 0; i <= samples; i += 1) {
    const phi = (2 * Math.PI * i) / samples;
    const uv = floorPointToPixel(scaled, radiusM * Math.cos(phi), radiusM * Math.sin(phi));
    if (uv === null) {
      if (run.length > 1) runs.push(run);
      run = [];
    } else {
      run.push(uv);
    }
  }
  if (run.length > 1) runs.push(run);
  return runs;
}

/** Camera floor frame (x, y) m -> site frame, by the camera's site pose (null without one). */
export function floorToSite(camera, x, y) {
  const pose = camera.site_pose;
  if (!pose) return null;
  const yaw = (pose.yaw_deg ?? 0) * deg;
  const c = Math.cos(yaw);
  const s = Math.sin(yaw);
  return [(pose.x_m ?? 0) + c * x - s * y, (pose.y_m ?? 0) + s * x + c * y];
}

/** A round step (1, 2 or 5 × 10^k) giving about `count` intervals over `span`. */
export function niceStep(span, count = 8) {
  const raw = span / count;
  const power = 10 ** Math.floor(Math.log10(raw));
  const mantissa = raw / power;
  const step = mantissa <= 1 ? 1 : mantissa <= 2 ? 2 : mantissa <= 5 ? 5 : 10;
  return step * power;
}
