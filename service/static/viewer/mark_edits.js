// Edits of ruler marks as pure functions: each takes the marks [{id, ruler, u, v, distance_m, x_m,
// y_m}] and returns new ones, or throws an Error that says why a typed value is refused.

/** The marks with the nadir (distance 0) at (u, v): the one there is moved, or one `id` put first. */
export function withNadir(marks, u, v, id) {
  if (marks.some((m) => m.distance_m === 0)) return marks.map((m) => (m.distance_m === 0 ? { ...m, u, v } : m));
  return [{ id, ruler: "nadir", u, v, distance_m: 0, x_m: null, y_m: null }, ...marks];
}

/** The marks with `field` (ruler, distance_m, x_m or y_m) of mark `id` set from the typed `text`. A
 *  floor position needs both coordinates (the other starts at 0), and the distance follows it. */
export function withEdit(marks, id, field, text) {
  const index = marks.findIndex((m) => m.id === id);
  if (index < 0) return marks;
  const mark = { ...marks[index] };
  if (field === "ruler") {
    mark.ruler = text.trim();
  } else {
    const value = text.trim() === "" ? null : Number(text);
    if (value !== null && !Number.isFinite(value)) throw new Error(`mark ${index + 1}: ${field} must be a number`);
    if (field === "distance_m") {
      if (value === null || value < 0) throw new Error(`mark ${index + 1}: the distance must be a number ≥ 0 (m)`);
      mark.distance_m = value;
    } else if (field === "x_m" || field === "y_m") {
      const other = field === "x_m" ? "y_m" : "x_m";
      mark[field] = value;
      mark[other] = value === null ? null : (mark[other] ?? 0);
      if (mark.x_m !== null) mark.distance_m = Math.hypot(mark.x_m, mark.y_m);
    } else {
      throw new Error(`marks have no field ${field}`);
    }
  }
  return marks.map((m, i) => (i === index ? mark : m));
}
