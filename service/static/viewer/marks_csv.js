// The marks.csv that `fishloc calibrate --marks` reads (fisheye/ruler_marks.py): a header row,
// then one ruler mark a row, `#` starting a comment line.
//
//   ruler,u,v,distance_m,x_m,y_m
//   east,1476,1476,0,,
//   east,1712,1476,1.0,,
//
// A mark here is {ruler, u, v, distance_m, x_m, y_m} with x_m, y_m null where unknown.

export const MARK_COLUMNS = ["ruler", "u", "v", "distance_m", "x_m", "y_m"];

/** The fields of one CSV line (commas; double quotes around a field may hold commas and "" quotes). */
function splitLine(line) {
  const fields = [];
  let field = "";
  let quoted = false;
  for (let i = 0; i < line.length; i += 1) {
    const c = line[i];
    if (quoted) {
      if (c === '"' && line[i + 1] === '"') { field += '"'; i += 1; }
      else if (c === '"') quoted = false;
      else field += c;
    } else if (c === '"' && field.trim() === "") {
      quoted = true;
      field = "";
    } else if (c === ",") {
      fields.push(field);
      field = "";
    } else {
      field += c;
    }
  }
  fields.push(field);
  return fields;
}

function quote(text) {
  return /[",\n]/.test(text) ? `"${text.replaceAll('"', '""')}"` : text;
}

/** The marks.csv text of `marks` (numbers written in full, empty x_m, y_m where unknown). */
export function marksToCsv(marks) {
  const cell = (value) => (value === null || value === undefined ? "" : String(value));
  const rows = marks.map((m) => [quote(m.ruler ?? ""), cell(m.u), cell(m.v), cell(m.distance_m), cell(m.x_m), cell(m.y_m)]);
  return [MARK_COLUMNS, ...rows].map((row) => row.join(",")).join("\n") + "\n";
}

/** Marks from the text of a marks.csv; throws an Error naming the line at the first problem. */
export function parseMarksCsv(text, source = "marks.csv") {
  const lines = text.split(/\r?\n/).map((line, i) => [i + 1, line])
    .filter(([, line]) => line.trim() !== "" && !line.trimStart().startsWith("#"));
  if (!lines.length) throw new Error(`${source} is empty`);
  const header = splitLine(lines[0][1]).map((name) => name.trim());
  const unknown = header.filter((name) => !MARK_COLUMNS.includes(name));
  if (unknown.length) throw new Error(`${source}: unknown column(s) ${unknown.join(", ")}; columns are ${MARK_COLUMNS.join(", ")}`);
  for (const required of ["u", "v"]) {
    if (!header.includes(required)) throw new Error(`${source}: column '${required}' is missing`);
  }
  if (!header.includes("distance_m") && !(header.includes("x_m") && header.includes("y_m"))) {
    throw new Error(`${source}: needs a distance_m column or x_m and y_m columns`);
  }
  const marks = lines.slice(1).map(([line, text]) => {
    const fields = splitLine(text);
    if (fields.length > header.length) throw new Error(`${source} line ${line}: more fields than the header names`);
    const row = Object.fromEntries(header.map((name, i) => [name, (fields[i] ?? "").trim()]));
    const number = (column) => {
      const value = row[column] ?? "";
      if (value === "") return null;
      const parsed = Number(value);
      if (!Number.isFinite(parsed)) throw new Error(`${source} line ${line}: ${column} must be a finite number, got '${value}'`);
      return parsed;
    };
    const [u, v, x, y] = [number("u"), number("v"), number("x_m"), number("y_m")];
    if (u === null || v === null) throw new Error(`${source} line ${line}: u and v are required`);
    if ((x === null) !== (y === null)) throw new Error(`${source} line ${line}: give both x_m and y_m or neither`);
    let distance = number("distance_m");
    if (distance === null) {
      if (x === null) throw new Error(`${source} line ${line}: give distance_m or both x_m and y_m`);
      distance = Math.hypot(x, y);
    }
    if (distance < 0) throw new Error(`${source} line ${line}: distance_m must be ≥ 0, got ${distance}`);
    return { ruler: row.ruler ?? "", u, v, distance_m: distance, x_m: x, y_m: y };
  });
  if (!marks.length) throw new Error(`${source} has a header but no marks`);
  return marks;
}
