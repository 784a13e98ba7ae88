// Masks: polygons [[u, v], ...] in frame pixels where nobody is counted (mirrors, posters, screens,
// glass). A camera stores them as `masks_px` at its `image_size`; the service drops a detection whose
// foot point falls inside one and refuses a polygon that crosses itself.

const EPS = 1e-9;

function cross(o, a, b) {
  return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
}

function onSegment(p, a, b) {
  return Math.min(a[0], b[0]) - EPS <= p[0] && p[0] <= Math.max(a[0], b[0]) + EPS &&
         Math.min(a[1], b[1]) - EPS <= p[1] && p[1] <= Math.max(a[1], b[1]) + EPS;
}

/** Whether segments ab and cd share a point (touching counts). */
export function segmentsIntersect(a, b, c, d) {
  const [d1, d2, d3, d4] = [cross(c, d, a), cross(c, d, b), cross(a, b, c), cross(a, b, d)];
  if (((d1 > EPS && d2 < -EPS) || (d1 < -EPS && d2 > EPS)) && ((d3 > EPS && d4 < -EPS) || (d3 < -EPS && d4 > EPS))) return true;
  return (Math.abs(d1) <= EPS && onSegment(a, c, d)) || (Math.abs(d2) <= EPS && onSegment(b, c, d)) ||
         (Math.abs(d3) <= EPS && onSegment(c, a, b)) || (Math.abs(d4) <= EPS && onSegment(d, a, b));
}

/** The first pair [i, j] of edges (edge i runs from point i to i + 1) of the closed polygon that
 *  cross or touch, neighbours excepted; null for a simple polygon. */
export function selfIntersection(points) {
  const n = points.length;
  for (let i = 0; i < n; i += 1) {
    for (let j = i + 2; j < n; j += 1) {
      if (i === 0 && j === n - 1) continue; // the closing edge meets the first at point 0
      if (segmentsIntersect(points[i], points[(i + 1) % n], points[j], points[(j + 1) % n])) return [i, j];
    }
  }
  return null;
}

/** What is wrong with a mask polygon for the page to say, or null. */
export function maskProblem(points, index) {
  if (points.length < 3) return `mask ${index + 1} has ${points.length} corners; it needs 3 or more`;
  const crossing = selfIntersection(points);
  return crossing ? `mask ${index + 1} crosses itself (edges ${crossing[0] + 1} and ${crossing[1] + 1})` : null;
}

/** Points [[u, v], ...] of frames `fromWh` -> frames `toWh` of the same view: u' = (u + 0.5)·s − 0.5. */
export function rescalePoints(points, fromWh, toWh) {
  const [su, sv] = [toWh[0] / fromWh[0], toWh[1] / fromWh[1]];
  return points.map(([u, v]) => [(u + 0.5) * su - 0.5, (v + 0.5) * sv - 0.5]);
}
