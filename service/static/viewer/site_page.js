// The live site map page (/site): pick a site, draw its cameras, zones and lines, and follow its
// occupancy as the service streams it (Server-Sent Events, /v1/sites/{site}/events): people as
// dots with their track ids and recent trails, zone counts, line tallies; and its counts history
// (site_history.js), drawn again at most every HISTORY_EVERY_MS while updates come. Routes: #/<site id>.

import { ApiError } from "./api.js";
import { fmt, fmtPair, html } from "./dom.js";
import { drawHistory, historyQuery } from "./site_history.js";
import { drawSiteMap, speedText } from "./site_map.js";

const $ = (id) => document.getElementById(id);

const state = {
  sites: [],          // [{id, cameras, zones}] of GET /v1/sites
  site: null,         // the shown site: {id, cameras: [{camera, origin, yawDeg}], zones, lines}
  occupancy: null,    // the latest occupancy answer or event
  updates: 0,         // occupancy events received for the shown site
  trails: new Map(),  // track id -> [{t, xy}], oldest first
  source: null,       // the EventSource of the shown site
  historyAt: 0,       // when (ms, page clock) the history was last asked for
};
const HISTORY_EVERY_MS = 10000;
window.fishlocSite = { state };

// With FISHLOC_READ_TOKEN set, site reads and events need it: asked for on a 401, kept for the tab.
const TOKEN_KEY = "fishloc-read-token";
const readToken = () => sessionStorage.getItem(TOKEN_KEY) || "";

async function getJson(path) {
  const headers = readToken() ? { Authorization: `Bearer ${readToken()}` } : {};
  const response = await fetch(path, { cache: "no-store", headers });
  if (!response.ok) {
    let body = null;
    try {
      body = await response.json();
    } catch {
      // not the JSON error shape
    }
    const error = body?.error ?? { code: "http_error", message: `${response.status} ${response.statusText}` };
    throw new ApiError(response.status, error.code, error.message);
  }
  return response.json();
}

function setStatus(text, isError = false) {
  $("status").textContent = text;
  $("status").classList.toggle("error", isError);
}

/** Zones and lines of GET /v1/sites/{site} as lists, whether it gives them keyed by id or listed. */
function entries(value, pick) {
  if (!value) return [];
  const listed = Array.isArray(value) ? value : Object.entries(value).map(([id, body]) => ({ id, ...body }));
  return listed.map(pick).filter((entry) => entry !== null);
}

async function loadSite(siteId) {
  const sitePath = `/v1/sites/${encodeURIComponent(siteId)}`;
  const [site, cameras] = await Promise.all([getJson(sitePath), getJson("/v1/cameras")]);
  const views = new Map((site.cameras ?? []).map((c) => (typeof c === "string" ? [c, null] : [c.id, c.view_m])));
  const posed = cameras.cameras.filter((c) => (c.site === siteId || views.has(c.id)) && c.site_pose);
  return {
    id: siteId,
    cameras: posed.map((camera) => ({
      camera, origin: [camera.site_pose.x_m ?? 0, camera.site_pose.y_m ?? 0], yawDeg: camera.site_pose.yaw_deg ?? 0,
      view: views.get(camera.id) ?? null,
    })),
    zones: entries(site.zones, (z) => (z.polygon_m ? { id: z.id, polygon: z.polygon_m } : null)),
    lines: entries(site.lines, (l) => (l.from_m && l.to_m ? { id: l.id, from: l.from_m, to: l.to_m } : null)),
  };
}

/** Keep each present track's positions of the last `seconds` (by the occupancy's own time). */
function updateTrails(occupancy, seconds) {
  const present = new Set();
  for (const person of occupancy.people ?? []) {
    if (!person.position_m) continue;
    present.add(person.track_id);
    const trail = state.trails.get(person.track_id) ?? [];
    const last = trail[trail.length - 1];
    if (!last || last.t !== occupancy.time) trail.push({ t: occupancy.time, xy: person.position_m });
    state.trails.set(person.track_id, trail.filter((p) => p.t >= occupancy.time - seconds));
  }
  for (const trackId of [...state.trails.keys()]) if (!present.has(trackId)) state.trails.delete(trackId);
}

function renderFigures(occupancy) {
  const site = state.site;
  $("zone-list").replaceChildren(...site.zones.map((zone) => html("li", { "data-zone": zone.id }, [
    html("span", { text: zone.id }), html("b", { text: String(occupancy?.zones?.[zone.id]?.count ?? 0) })])));
  $("line-list").replaceChildren(...site.lines.map((line) => {
    const tally = occupancy?.lines?.[line.id] ?? { in: 0, out: 0 };
    return html("li", { "data-line": line.id, "data-in": tally.in, "data-out": tally.out }, [
      html("span", { text: line.id }), html("b", { text: `in ${tally.in} · out ${tally.out}` })]);
  }));
  const people = occupancy?.people ?? [];
  $("tracks").querySelector("tbody").replaceChildren(...people.map((p) => html("tr", { "data-track": p.track_id }, [
    html("td", { text: p.track_id }), html("td", { class: "position", text: fmtPair(p.position_m, 2) }),
    html("td", { text: speedText(p.velocity_mps) }), html("td", { text: (p.cameras ?? []).join(", ") }),
    html("td", { text: fmt(p.last_seen - p.first_seen, 1) }),
    html("td", { text: Object.entries(p.dwell_s ?? {}).map(([z, s]) => `${z} ${fmt(s, 0)} s`).join(", ") }),
  ])));
  const when = occupancy?.time ? new Date(occupancy.time * 1000).toISOString().replace("T", " ").slice(0, 22) : "–";
  $("site-info").textContent = `${site.cameras.length} cameras, ${occupancy?.count ?? 0} people at ${when} UTC` +
    ` (${state.updates} updates)`;
}

function render() {
  if (!state.site) return;
  drawSiteMap($("live-map"), {
    cameras: state.site.cameras, zones: state.site.zones, lines: state.site.lines, occupancy: state.occupancy,
    trails: new Map([...state.trails].map(([id, points]) => [id, points.map((p) => p.xy)])),
    withViews: $("map-extent").value === "views",
  });
  renderFigures(state.occupancy);
  document.body.dataset.updates = String(state.updates);
}

function accept(occupancy) {
  if (!occupancy || occupancy.site !== state.site?.id) return;
  if (state.occupancy && occupancy.time < state.occupancy.time) return; // an older update, late
  state.occupancy = occupancy;
  updateTrails(occupancy, Number($("trail-seconds").value));
  render();
  if (performance.now() - state.historyAt > HISTORY_EVERY_MS) loadHistory();
}

async function loadHistory() {
  const site = state.site;
  if (!site) return;
  state.historyAt = performance.now();
  const endS = state.occupancy?.time ?? Date.now() / 1000;
  const query = historyQuery(site.id, endS, $("history-range").value);
  $("history-csv").href = `${query.path}&format=csv`;
  const chart = $("history-chart");
  try {
    const history = await getJson(query.path);
    if (state.site?.id !== site.id) return;
    drawHistory(chart, history.rows, query);
    chart.dataset.state = "drawn";
    chart.dataset.range = $("history-range").value;
  } catch (error) {
    chart.dataset.state = "error";
    setStatus(`history: ${error.message}`, true);
  }
}

function setLive(live) {
  $("live").dataset.live = live ? "on" : "off";
  $("live").textContent = live ? "live" : "reconnecting…";
}

function follow(siteId) {
  state.source?.close();
  const query = readToken() ? `?${new URLSearchParams({ access_token: readToken() })}` : "";
  const source = new EventSource(`/v1/sites/${encodeURIComponent(siteId)}/events${query}`);
  state.source = source;
  const onEvent = (event) => {
    state.updates += 1;
    accept(JSON.parse(event.data));
  };
  source.addEventListener("occupancy", onEvent);
  source.addEventListener("open", () => {
    setLive(true);
    document.body.dataset.state = "live";
  });
  source.addEventListener("error", () => setLive(false)); // EventSource reconnects by itself
  source.addEventListener("end", () => { // the site has no camera left
    source.close();
    setLive(false);
    $("live").textContent = "site closed";
  });
}

async function showSite(siteId) {
  document.body.dataset.state = "loading";
  state.source?.close();
  state.source = null;
  state.updates = 0;
  state.trails = new Map();
  state.occupancy = null;
  state.site = await loadSite(siteId);
  $("site-title").textContent = siteId;
  for (const link of $("site-list").querySelectorAll("a")) link.classList.toggle("active", link.dataset.site === siteId);
  accept(await getJson(`/v1/sites/${encodeURIComponent(siteId)}/occupancy`));
  render();
  await loadHistory();
  follow(siteId);
}

function renderSiteList() {
  $("site-list").replaceChildren(...state.sites.map((site) => html("li", {}, [
    html("a", { href: `#/${encodeURIComponent(site.id)}`, "data-site": site.id, text: site.id })])));
}

async function route() {
  const wanted = decodeURIComponent(location.hash.replace(/^#\/?/, ""));
  const siteId = state.sites.some((s) => s.id === wanted) ? wanted : state.sites[0]?.id;
  if (!siteId) {
    document.body.dataset.state = "empty";
    setStatus("No site yet: give cameras a `site` and a `site_pose` (PUT /v1/cameras/{id}).");
    return;
  }
  try {
    await showSite(siteId);
    setStatus("");
  } catch (error) {
    document.body.dataset.state = "error";
    setStatus(`${siteId}: ${error.message}`, true);
  }
}

async function main() {
  $("read-token").addEventListener("change", () => {
    sessionStorage.setItem(TOKEN_KEY, $("read-token").value);
    location.reload();
  });
  try {
    state.sites = (await getJson("/v1/sites")).sites;
  } catch (error) {
    document.body.dataset.state = error.status === 401 ? "token" : "error";
    $("token-field").hidden = error.status !== 401;
    setStatus(error.status === 401 ? "This service guards where people are: enter its read token."
      : `cannot list the sites: ${error.message}`, true);
    return;
  }
  renderSiteList();
  window.addEventListener("hashchange", route);
  $("trail-seconds").addEventListener("change", render);
  $("map-extent").addEventListener("change", render);
  $("history-range").addEventListener("change", loadHistory);
  $("history-refresh").addEventListener("click", loadHistory);
  window.addEventListener("resize", render);
  await route();
}

main();
