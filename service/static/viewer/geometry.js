// Camera geometry for drawing and checking: floor (x, y) m <-> frame pixel, as in fisheye/camera.py
// (FisheyeCamera.scaled_to, floor_to_pixels, pixels_to_floor), fisheye/lens.py and DESIGN.md's
// conventions. Pixels: u right, v down, centres at integers. Floor frame: origin at the nadir, x
// towards image right, y towards image top, z up. r(θ) = k1·θ + k2·θ³ + ... (Kannala–Brandt). A
// camera with `tilt_deg` [a, b] turns each lens ray by a about x, then by b about y.

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

/** dr/dθ of the lens polynomial. */
function radiusDerivative(thetaRad, kb) {
  const t2 = thetaRad * thetaRad;
  let slope = 0;
  for (let i = kb.length - 1; i >= 0; i -= 1) slope = slope * t2 + (2 * i + 1) * kb[i];
  return slope;
}

/** θ (rad) with r(θ) = radius, or null outside [0, r(θmax)]: Newton kept inside a shrinking
 *  bracket, finished by bisection (as fisheye/lens.py radius_to_theta). */
export function radiusToTheta(radius, kb, thetaMaxRad) {
  const radiusMax = thetaToRadius(thetaMaxRad, kb);
  if (!(radius >= 0 && radius <= radiusMax * (1 + 1e-12))) return null;
  const goal = Math.min(radius, radiusMax);
  let [lo, hi] = [0, thetaMaxRad];
  let theta = Math.min(Math.max(goal / kb[0], 0), thetaMaxRad);
  for (let i = 0; i < 30; i += 1) {
    const residual = thetaToRadius(theta, kb) - goal;
    if (residual === 0) return theta;
    if (residual < 0) lo = theta; else hi = theta;
    let next = theta - residual / radiusDerivative(theta, kb);
    if (!Number.isFinite(next) || next < lo || next > hi) next = 0.5 * (lo + hi);
    if (Math.abs(next - theta) < 1e-12) return next;
    theta = next;
  }
  for (let i = 0; i < 80; i += 1) {
    const middle = 0.5 * (lo + hi);
    if (thetaToRadius(middle, kb) < goal) lo = middle; else hi = middle;
  }
  return 0.5 * (lo + hi);
}

/** The rotation lens ray -> floor frame of a camera's `tilt_deg` [a, b]: R_y(b)·R_x(a), rows. */
function tiltMatrix(camera) {
  const [a, b] = (camera.tilt_deg ?? [0, 0]).map((angle) => angle * deg);
  const [ca, sa, cb, sb] = [Math.cos(a), Math.sin(a), Math.cos(b), Math.sin(b)];
  return [[cb, sb * sa, sb * ca], [0, ca, -sa], [-sb, cb * sa, cb * ca]];
}

/** One floor point (x, y) m -> [u, v] px of a camera already scaled to the frame; null beyond θmax. */
export function floorPointToPixel(camera, x, y) {
  const ray = [x, y, -camera.altitude_m];
  const m = tiltMatrix(camera);
  // Floor-frame ray -> lens ray: the transpose of the tilt rotation.
  const [lx, ly, lz] = [0, 1, 2].map((j) => m[0][j] * ray[0] + m[1][j] * ray[1] + m[2][j] * ray[2]);
  const horizontal = Math.hypot(lx, ly);
  const theta = Math.atan2(horizontal, -lz);
  if (theta > thetaMaxDeg(camera) * deg + 1e-12) return null;
  const r = thetaToRadius(theta, camera.kb);
  const cosPhi = horizontal > 0 ? lx / horizontal : 1;
  const sinPhi = horizontal > 0 ? ly / horizontal : 0;
  const [u0, v0] = camera.principal_point;
  const [fx, fy] = camera.focal_px;
  return [u0 + fx * r * cosPhi, v0 - fy * r * sinPhi];
}

/** One pixel [u, v] of a camera already scaled to the frame -> floor [x, y] m; null where its ray
 *  leaves the calibrated field or misses the floor. */
export function pixelToFloorPoint(camera, u, v) {
  const [u0, v0] = camera.principal_point;
  const [fx, fy] = camera.focal_px;
  const xn = (u - u0) / fx;
  const yn = -(v - v0) / fy;
  const theta = radiusToTheta(Math.hypot(xn, yn), camera.kb, thetaMaxDeg(camera) * deg);
  if (theta === null) return null;
  const phi = Math.atan2(yn, xn);
  const lens = [Math.sin(theta) * Math.cos(phi), Math.sin(theta) * Math.sin(phi), -Math.cos(theta)];
  const [rx, ry, rz] = tiltMatrix(camera).map((row) => row[0] * lens[0] + row[1] * lens[1] + row[2] * lens[2]);
  if (!(rz < 0)) return null;
  const t = camera.altitude_m / -rz;
  return [t * rx, t * ry];
}

/** Pixels [[u, v], ...] in frames of `resolutionWh` -> [[x, y] | null, ...] m on the floor. */
export function pixelsToFloor(camera, resolutionWh, points) {
  const scaled = scaledCamera(camera, resolutionWh);
  return points.map(([u, v]) => pixelToFloorPoint(scaled, u, v));
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
