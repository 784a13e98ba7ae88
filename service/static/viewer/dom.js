// Small helpers for building SVG and HTML elements.

const SVG_NS = "http://www.w3.org/2000/svg";

/** An SVG element with attributes (null/undefined ones left out) and children. */
export function svg(tag, attrs = {}, children = []) {
  const node = document.createElementNS(SVG_NS, tag);
  for (const [name, value] of Object.entries(attrs)) {
    if (value !== null && value !== undefined) node.setAttribute(name, String(value));
  }
  for (const child of children) node.append(child);
  return node;
}

/** An HTML element with attributes, `text` for text content, and children. */
export function html(tag, attrs = {}, children = []) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) {
    if (value === null || value === undefined) continue;
    if (name === "text") node.textContent = String(value);
    else node.setAttribute(name, String(value));
  }
  for (const child of children) node.append(child);
  return node;
}

/** SVG `points` attribute of [[x, y], ...]. */
export function pointsAttr(points) {
  return points.map(([x, y]) => `${x},${y}`).join(" ");
}

/** A number for display with `digits` decimals, or "–" for null. */
export function fmt(value, digits = 2) {
  return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
}

export function fmtPair(pair, digits = 2) {
  return pair ? `(${fmt(pair[0], digits)}, ${fmt(pair[1], digits)})` : "–";
}
