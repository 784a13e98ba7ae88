// The Calibrate mode's side panel, drawn from its state (calibrate.js): the fit's RMS, refusal and
// notes, whether the camera is saved, the masks and the marks table with each mark's residual.

import { fmt, fmtPair, html } from "./dom.js";
import { maskProblem } from "./masks.js";

const $ = (id) => document.getElementById(id);

function numberCell(mark, field, digits) {
  const value = mark[field];
  return html("td", {}, [html("input", {
    type: "number", step: "any", "data-mark-id": mark.id, "data-field": field, size: 6,
    value: value === null ? "" : +value.toFixed(digits),
  })]);
}

function renderMarksTable(cal, byId) {
  const active = document.activeElement;
  // A value being typed survives the redraw that a finished fit brings.
  const focused = active?.dataset?.field && $("cal-marks").contains(active)
    ? { ...active.dataset, value: active.value } : null;
  const rows = cal.marks.map((mark, index) => {
    const residual = byId.get(mark.id);
    return html("tr", { "data-mark-id": mark.id, class: mark.id === cal.selected ? "selected" : null }, [
      html("td", { text: mark.distance_m === 0 ? `${index + 1} nadir` : index + 1 }),
      html("td", {}, [html("input", { "data-mark-id": mark.id, "data-field": "ruler", value: mark.ruler, size: 6 })]),
      numberCell(mark, "distance_m", 4), numberCell(mark, "x_m", 4), numberCell(mark, "y_m", 4),
      html("td", { text: fmtPair([mark.u, mark.v], 1) }),
      html("td", { class: "err-m", text: residual && residual.err_m !== null ? fmt(residual.err_m * 100, 1) : "–" }),
      html("td", { class: "err-px", text: residual && residual.err_px !== null ? fmt(residual.err_px, 2) : "–" }),
      html("td", {}, [html("button", { type: "button", class: "delete", "data-mark-id": mark.id, title: "delete", text: "✕" })]),
    ]);
  });
  $("cal-marks").querySelector("tbody").replaceChildren(...rows);
  const again = focused && $("cal-marks").querySelector(`input[data-mark-id="${focused.markId}"][data-field="${focused.field}"]`);
  if (again) {
    again.value = focused.value;
    again.focus();
  }
}

function renderMasks(cal) {
  const items = cal.masks.map((points, index) => {
    const problem = maskProblem(points, index);
    return html("li", { "data-mask": index, class: problem ? "error" : null }, [
      problem ?? `mask ${index + 1}: ${points.length} corners`, " ",
      html("button", { type: "button", class: "delete", "data-mask": index, text: "✕" }),
    ]);
  });
  if (cal.drawing.length) items.push(html("li", { class: "muted", text: `drawing: ${cal.drawing.length} corners` }));
  $("cal-masks").replaceChildren(...items);
}

function renderResult(cal, scaledTo) {
  const fit = cal.fit;
  $("cal-rms").textContent = fit
    ? `RMS ${fmt(fit.rms_m * 100, 2)} cm, ${fmt(fit.rms_px, 2)} px over ${fit.marks.length} marks` +
      (cal.fitting ? " (fitting…)" : "")
    : (cal.fitting ? "fitting…" : "");
  $("cal-error").textContent = cal.fitError ?? "";
  const circle = cal.circle?.circle;
  $("cal-circle-info").textContent = circle
    ? `image circle: centre ${fmtPair(circle.center_px, 1)} px, radius ${fmt(circle.radius_px, 1)} px, ` +
      `${fmt(circle.cut.visible_rim_fraction * 100, 0)} % of its rim in the frame, ` +
      `${fmt(circle.inlier_fraction * 100, 0)} % of rim points on it, RMS ${fmt(circle.rms_px, 2)} px`
    : "";
  // A note is {code, level, message} (or a plain message): warnings say what to add or change.
  const notes = (fit ? fit.notes : []).map((note) => (typeof note === "string" ? { message: note } : note));
  $("cal-notes").replaceChildren(...notes.map((note) => html("li", {
    class: note.level === "warning" ? "warning" : null, "data-code": note.code ?? null, text: note.message,
  })));
  const sizeNote = scaledTo ? ` · marks scaled to ${scaledTo[0]}×${scaledTo[1]} px` : "";
  $("cal-frame-info").textContent = cal.frame
    ? `${cal.frame.source}: ${cal.frame.width}×${cal.frame.height} px${sizeNote} · wheel: zoom at the pointer · ` +
      "drag: pan, or move a mark · click: the tool"
    : "no frame yet";
  $("cal-saved").textContent = cal.unsaved ? "not saved: the registry still has the previous calibration"
    : cal.saves ? "saved" : "";
}

/** Draw the panel of state `cal`; `residuals` maps mark ids to the fit's marks, `scaledTo` is the
 *  image size [W, H] when the frame has another size (else null). */
export function renderPanel(cal, residuals, scaledTo) {
  renderMarksTable(cal, residuals);
  renderMasks(cal);
  renderResult(cal, scaledTo);
}
