// The counts history chart of the site page: GET /v1/sites/{site}/history over a range that ends at
// the site's newest capture time (history is kept in capture time), drawn as SVG: people per step
// (mean as a line, max as a lighter line) over bars of the line crossings (in + out) per step.

import { svg, pointsAttr } from "./dom.js";

export const RANGES = {
  hour: { spanS: 3600, stepS: 60 },
  day: { spanS: 86400, stepS: 900 },
  week: { spanS: 7 * 86400, stepS: 3600 },
  month: { spanS: 30 * 86400, stepS: 86400 },
};

const WIDTH = 600;
const HEIGHT = 180;
const PAD = { left: 34, right: 8, top: 10, bottom: 20 };

/** The history query of a range ending at `endS` (Unix s): {path, fromS, toS, stepS}. */
export function historyQuery(siteId, endS, rangeKey) {
  const { spanS, stepS } = RANGES[rangeKey] ?? RANGES.hour;
  const toS = Math.floor(endS / stepS) * stepS + stepS;
  const fromS = toS - spanS;
  const query = new URLSearchParams({ from: String(fromS), to: String(toS), step: String(stepS) });
  return { path: `/v1/sites/${encodeURIComponent(siteId)}/history?${query}`, fromS, toS, stepS };
}

function timeLabel(seconds, stepS) {
  const iso = new Date(seconds * 1000).toISOString();
  return stepS >= 86400 ? iso.slice(5, 10) : iso.slice(11, 16);
}

/** Draw history `rows` (the route's) of the range {fromS, toS, stepS} into the <svg> `root`. */
export function drawHistory(root, rows, { fromS, toS, stepS }) {
  const plotW = WIDTH - PAD.left - PAD.right;
  const plotH = HEIGHT - PAD.top - PAD.bottom;
  const x = (t) => PAD.left + ((t - fromS) / (toS - fromS)) * plotW;
  const crossings = rows.map((row) => Object.values(row.lines ?? {}).reduce((n, l) => n + l.in + l.out, 0));
  const peopleTop = Math.max(1, ...rows.map((row) => row.people_max));
  const crossTop = Math.max(1, ...crossings);
  const yPeople = (v) => PAD.top + plotH - (v / peopleTop) * plotH;
  const barW = Math.max(1, (stepS / (toS - fromS)) * plotW - 1);
  const bars = rows.map((row, i) => {
    const h = (crossings[i] / crossTop) * plotH * 0.5;
    const sums = Object.values(row.lines ?? {}).reduce((s, l) => [s[0] + l.in, s[1] + l.out], [0, 0]);
    return svg("rect", { class: "crossings", x: x(row.time), y: PAD.top + plotH - h, width: barW, height: h,
                         "data-time": row.time, "data-in": sums[0], "data-out": sums[1] });
  });
  const middle = (row) => x(row.time + stepS / 2);
  const mean = svg("polyline", { class: "people-mean",
                                 points: pointsAttr(rows.map((row) => [middle(row), yPeople(row.people_mean)])) });
  const peak = svg("polyline", { class: "people-max",
                                 points: pointsAttr(rows.map((row) => [middle(row), yPeople(row.people_max)])) });
  const axis = [
    svg("line", { class: "axis", x1: PAD.left, y1: PAD.top + plotH, x2: WIDTH - PAD.right, y2: PAD.top + plotH }),
    svg("text", { class: "axis-label", x: 2, y: PAD.top + 8 }, [document.createTextNode(`${peopleTop} p`)]),
    svg("text", { class: "axis-label", x: PAD.left, y: HEIGHT - 4 },
        [document.createTextNode(timeLabel(fromS, stepS))]),
    svg("text", { class: "axis-label", x: WIDTH - PAD.right, y: HEIGHT - 4, "text-anchor": "end" },
        [document.createTextNode(`${timeLabel(toS, stepS)} UTC`)]),
  ];
  root.setAttribute("viewBox", `0 0 ${WIDTH} ${HEIGHT}`);
  root.replaceChildren(...axis, svg("g", { class: "bars" }, bars), peak, mean);
  root.dataset.rows = String(rows.length);
  root.dataset.crossings = String(crossings.reduce((a, b) => a + b, 0));
  root.dataset.peopleMax = String(rows.length ? Math.max(...rows.map((row) => row.people_max)) : 0);
}
