// Zoom and pan over an <svg> drawn in frame pixels (viewBox from (-0.5, -0.5)), up to many screen
// pixels per frame pixel, and the pointer gestures on it: a click (press and release without
// moving), a drag of a marked element (any with data-drag), or a drag of the background (pan).

const CLICK_SLOP_PX = 4;       // a press that moves less than this is a click
const WHEEL_HALVING = 240;     // wheel delta (px) that zooms by 2×
const MAX_SCREEN_PER_FRAME = 40;

/**
 * Attach to `root` (an <svg>). handlers: click(u, v, event, element or null), dragStart(element, u, v)
 * -> bool (true to take the drag), drag(u, v), dragEnd(u, v), view() after every zoom or pan. Returns the controller: setFrame(width, height),
 * whole(), oneToOne(), zoomAt(u, v, factor), toFrame(clientX, clientY), toClient(u, v), view().
 */
export function attachZoomPan(root, handlers) {
  let frame = { width: 1, height: 1 };
  let box = { x: -0.5, y: -0.5, w: 1, h: 1 };
  let press = null; // {id, x, y, moved, element, dragging, panFrom}

  const apply = () => {
    root.setAttribute("viewBox", `${box.x} ${box.y} ${box.w} ${box.h}`);
    handlers.view?.();
  };

  const toFrame = (clientX, clientY) => {
    const point = new DOMPoint(clientX, clientY).matrixTransform(root.getScreenCTM().inverse());
    return [point.x, point.y];
  };
  const toClient = (u, v) => {
    const point = new DOMPoint(u, v).matrixTransform(root.getScreenCTM());
    return [point.x, point.y];
  };
  /** Screen pixels per frame pixel at the present zoom (1 while the drawing is hidden). */
  const scale = () => root.getScreenCTM()?.a || 1;

  function whole() {
    box = { x: -0.5, y: -0.5, w: frame.width, h: frame.height };
    apply();
  }

  function zoomAt(u, v, factor) {
    const fitScale = scale() * (frame.width / box.w); // screen px per frame px when whole
    const wanted = Math.min(Math.max(scale() * factor, fitScale), MAX_SCREEN_PER_FRAME);
    const f = wanted / scale();
    box = { x: u - (u - box.x) / f, y: v - (v - box.y) / f, w: box.w / f, h: box.h / f };
    apply();
  }

  function oneToOne() {
    const [u, v] = [box.x + box.w / 2, box.y + box.h / 2];
    zoomAt(u, v, 1 / scale());
  }

  root.addEventListener("wheel", (event) => {
    event.preventDefault();
    const [u, v] = toFrame(event.clientX, event.clientY);
    zoomAt(u, v, 2 ** (-event.deltaY / WHEEL_HALVING));
  }, { passive: false });

  root.addEventListener("pointerdown", (event) => {
    if (event.button !== 0 || press) return;
    const element = event.target.closest?.("[data-drag]") ?? null;
    press = { id: event.pointerId, x: event.clientX, y: event.clientY, moved: false, element, dragging: false,
              panFrom: { ...box } };
    root.setPointerCapture(event.pointerId);
  });

  root.addEventListener("pointermove", (event) => {
    if (!press || event.pointerId !== press.id) return;
    const dx = event.clientX - press.x;
    const dy = event.clientY - press.y;
    if (!press.moved && Math.hypot(dx, dy) < CLICK_SLOP_PX) return;
    if (!press.moved) {
      press.moved = true;
      const [u, v] = toFrame(press.x, press.y);
      press.dragging = Boolean(press.element && handlers.dragStart?.(press.element, u, v));
    }
    if (press.dragging) {
      handlers.drag?.(...toFrame(event.clientX, event.clientY));
    } else {
      const s = scale();
      box = { ...box, x: press.panFrom.x - dx / s, y: press.panFrom.y - dy / s };
      apply();
      press.panFrom = { ...box };
      press.x = event.clientX;
      press.y = event.clientY;
    }
  });

  const release = (event) => {
    if (!press || event.pointerId !== press.id) return;
    const done = press;
    press = null;
    if (root.hasPointerCapture(event.pointerId)) root.releasePointerCapture(event.pointerId);
    if (event.type === "pointercancel") return;
    const [u, v] = toFrame(event.clientX, event.clientY);
    if (done.dragging) handlers.dragEnd?.(u, v);
    else if (!done.moved) handlers.click?.(u, v, event, done.element);
  };
  root.addEventListener("pointerup", release);
  root.addEventListener("pointercancel", release);

  return {
    setFrame(width, height) {
      frame = { width, height };
      whole();
    },
    whole,
    oneToOne,
    zoomAt,
    toFrame,
    toClient,
    view: () => ({ ...box, screenPerFrame: scale() }),
  };
}
