/* saim-mesh commander's console: the page (docs/console.md section 3).
 * Plain JavaScript, no build step. Reads GET /api/state once, then live updates from the
 * server-sent events at /events (no polling); actions POST to /api/<kind>. */
(function () {
  "use strict";

  const PRIORITIES = ["flash", "immediate", "priority", "routine"];
  const PANE_CAP = 200;          // DOM rows kept per pane (the newest)
  const MODEL_CAP = 200000;      // alerts kept in memory
  const RENDER_LOG_CAP = 100000;
  const STATUS_LOG_CAP = 30;

  window.__renderLog = [];
  window.__alertsSeen = 0;
  // The mesh clock: [scenario t, wall ms the replay published that tick], in order. An
  // alert raised at t is due on the mesh at the first tick at or after t; its latency is
  // from that tick's publication to the alert's row on screen (same machine, same clock).
  const TICK_LOG_CAP = 400000;
  window.__ticks = [];
  window.__latencies = function () {
    const ticks = window.__ticks, out = [];
    for (const e of window.__renderLog) {
      let lo = 0, hi = ticks.length;   // first tick with t >= the alert's t
      while (lo < hi) { const mid = (lo + hi) >> 1; if (ticks[mid][0] < e.t_alert) lo = mid + 1; else hi = mid; }
      const due = lo < ticks.length ? ticks[lo][1] : null;
      out.push(Object.assign({}, e, { due_ms: due, latency_ms: due === null ? null : e.rendered_ms - due }));
    }
    return out;
  };

  // ---------------------------------------------------------------- state
  const S = {
    scenario: "", unit: null, units: {}, overlay: null, positions: {}, tracks: {},
    counts: {}, t: 0, actors: [],
    alerts: [],                 // every alert received, arrival order
    ids: new Set(),             // alert ids seen (dedupe between snapshot and stream)
    byId: new Map(),
    filter: "all",
    selected: null,             // the alert shown in #details
    acked: new Set(),
    types: new Set(), cffs: new Set(),
  };
  let localSeq = 0;

  const $ = (id) => document.getElementById(id);
  const el = (tag, cls, text) => {
    const e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined && text !== null) e.textContent = text;
    return e;
  };

  function hms(t) {
    t = Math.round(Number(t) || 0);
    const sign = t < 0 ? "-" : "+";
    t = Math.abs(t);
    const p = (n) => String(n).padStart(2, "0");
    return `H${sign}${p(Math.floor(t / 3600))}:${p(Math.floor((t % 3600) / 60))}:${p(t % 60)}`;
  }

  function alertId(a) {
    if (a.details && typeof a.details.id === "string") return a.details.id;
    if (!a.__lid) a.__lid = `${a.owner || "?"}/local-${++localSeq}`;
    return a.__lid;
  }

  // ---------------------------------------------------------------- status
  function setStatus(text, ok) {
    const s = $("status");
    s.textContent = text;
    s.className = "status " + (ok ? "ok" : "err");
    logStatus(text, ok);
  }
  function logStatus(text, ok) {
    const log = $("status-log");
    const li = el("li", ok ? "" : "err", `${new Date().toLocaleTimeString()} ${text}`);
    log.insertBefore(li, log.firstChild);
    while (log.childNodes.length > STATUS_LOG_CAP) log.removeChild(log.lastChild);
  }

  // ---------------------------------------------------------------- map
  let map = null;
  const overlayById = new Map();     // overlay id -> {layer, kind, style}
  const unitMarkers = new Map();     // unit id -> marker
  const trackMarkers = new Map();    // track id -> marker
  let graticule = null;
  let highlighted = [];              // [{kind: "overlay"|"unit"|"track", id}]
  const iconCache = new Map();

  const OVERLAY_STYLE = {
    "boundary": { color: "#111", weight: 2.5, dashArray: "10 4 2 4", fill: false },
    "route": { color: "#1d4ed8", weight: 3, opacity: 0.8 },
    "phase-line": { color: "#111", weight: 2, dashArray: "8 6" },
    "objective": { color: "#111", weight: 2, fillColor: "#111", fillOpacity: 0.06 },
    "battle-position": { color: "#1d4ed8", weight: 1.5, fillColor: "#1d4ed8", fillOpacity: 0.06 },
    "decision-point": { radius: 7, color: "#b45309", weight: 2, fillColor: "#fbbf24", fillOpacity: 0.7 },
    "nai": { radius: 7, color: "#047857", weight: 2, dashArray: "4 3", fillColor: "#34d399", fillOpacity: 0.25 },
    "avenue-of-approach": { color: "#dc2626", weight: 4, opacity: 0.7, dashArray: "14 8" },
    "engagement-area": { color: "#dc2626", weight: 1.5, fillColor: "#dc2626", fillOpacity: 0.08 },
    "checkpoint": { radius: 5, color: "#111", weight: 2, fillColor: "#fff", fillOpacity: 1 },
    "assembly-area": { color: "#1d4ed8", weight: 1.5, dashArray: "3 3", fillColor: "#1d4ed8", fillOpacity: 0.04 },
    "area": { color: "#6b7280", weight: 1, fillColor: "#6b7280", fillOpacity: 0.05 },
    // UV-Robotics world
    "obstacle": { color: "#374151", weight: 1, fillColor: "#4b5563", fillOpacity: 0.6 },
    "waypoint": { radius: 5, color: "#7c3aed", weight: 2, fillColor: "#ede9fe", fillOpacity: 1 },
    "patrol-area": { color: "#15803d", weight: 2, dashArray: "6 4", fillColor: "#22c55e", fillOpacity: 0.07 },
    "sector": { color: "#7c3aed", weight: 1, fillColor: "#7c3aed", fillOpacity: 0.03 },
    "base": { radius: 7, color: "#111", weight: 2, fillColor: "#93c5fd", fillOpacity: 1 },
  };
  const DEFAULT_STYLE = { color: "#555", weight: 1.5, fillOpacity: 0.05, radius: 5, fillColor: "#999" };
  const HL_STYLE = { color: "#ff00d4", weight: 5, opacity: 1, fillColor: "#ff00d4", fillOpacity: 0.25 };
  const LABEL_ALWAYS = new Set(["objective", "decision-point", "nai", "checkpoint", "waypoint",
    "engagement-area", "avenue-of-approach", "base", "patrol-area", "assembly-area"]);

  function initMap() {
    map = L.map("map", { crs: L.CRS.EPSG3857, zoomSnap: 0.25, zoomControl: true, attributionControl: false,
      preferCanvas: false, minZoom: 3, maxZoom: 20, center: [0, 0], zoom: 3 });
    const tiles = new URLSearchParams(location.search).get("tiles");
    if (tiles) L.tileLayer(tiles, { maxZoom: 20 }).addTo(map);
    map.createPane("graticule").style.zIndex = 250;
    map.createPane("units").style.zIndex = 620;
    graticule = L.layerGroup().addTo(map);
    map.on("moveend zoomend resize", drawGraticule);
    map.on("zoomend", () => declutter());
    L.control.scale({ imperial: false }).addTo(map);
  }

  function graticuleStep(span) {
    const steps = [0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 30];
    for (const s of steps) if (span / s <= 12) return s;
    return 30;
  }

  function drawGraticule() {
    if (!map || !graticule) return;
    graticule.clearLayers();
    const b = map.getBounds();
    const s = b.getSouth(), n = b.getNorth(), w = b.getWest(), e = b.getEast();
    const step = graticuleStep(Math.max(n - s, e - w));
    const dec = Math.max(0, Math.ceil(-Math.log10(step)));
    const style = { pane: "graticule", color: "#9ca3af", weight: 0.7, opacity: 0.7, interactive: false };
    const n0 = Math.max(-85, s), n1 = Math.min(85, n);
    for (let lat = Math.ceil(n0 / step) * step; lat <= n1; lat += step) {
      graticule.addLayer(L.polyline([[lat, w], [lat, e]], style));
      graticule.addLayer(L.marker([lat, w], { pane: "graticule", interactive: false, icon: L.divIcon({
        className: "grat-label", html: `${lat.toFixed(dec)}°`, iconSize: [60, 12], iconAnchor: [-2, 12] }) }));
    }
    for (let lon = Math.ceil(w / step) * step; lon <= e; lon += step) {
      graticule.addLayer(L.polyline([[n0, lon], [n1, lon]], style));
      graticule.addLayer(L.marker([s, lon], { pane: "graticule", interactive: false, icon: L.divIcon({
        className: "grat-label", html: `${lon.toFixed(dec)}°`, iconSize: [70, 12], iconAnchor: [-2, 14] }) }));
    }
  }

  function overlayStyle(kind) {
    return Object.assign({}, DEFAULT_STYLE, OVERLAY_STYLE[kind] || {});
  }

  function loadOverlay(gj) {
    if (!gj || !gj.features) return;
    overlayById.clear();
    const layer = L.geoJSON(gj, {
      style: (f) => overlayStyle((f.properties || {}).kind),
      pointToLayer: (f, latlng) => L.circleMarker(latlng, overlayStyle((f.properties || {}).kind)),
      onEachFeature: (f, lyr) => {
        const p = f.properties || {};
        const kind = p.kind || "";
        if (p.id) {
          overlayById.set(p.id, { layer: lyr, kind, style: overlayStyle(kind) });
          addOption($("overlay-ids"), p.id);   // silences by area name places
        }
        const label = p.id || p.name || kind;
        if (label) {
          const always = LABEL_ALWAYS.has(kind);
          lyr.bindTooltip(String(label), { permanent: always, direction: "center", className: "ov-label",
            sticky: !always && f.geometry && f.geometry.type !== "Point" });
        }
        const rows = Object.entries(p).map(([k, v]) => `<b>${esc(k)}</b>: ${esc(fmt(v))}`).join("<br>");
        lyr.bindPopup(rows);
      },
    }).addTo(map);
    const b = layer.getBounds();
    if (b.isValid()) map.fitBounds(b, { padding: [10, 10], animate: false });
    baseZoom = map.getZoom();
    drawGraticule();
    declutter();
  }

  function sidcFor(unitId) {
    const u = S.units[unitId] || {};
    const kind = String(u.kind || u.echelon || "").toLowerCase();
    switch (kind) {
      case "ugv": return "SFGPEV---------";
      case "uav": return "SFAPMFQ--------";
      case "usv": return "SFSPXR---------";
      case "team": case "crew": return "SFGPU------A";
      case "squad": return "SFGPU------B";
      case "section": return "SFGPU------C";
      case "platoon": return "SFGPU------D";
      case "company": case "battery": case "troop": return "SFGPU------E";
      case "battalion": case "squadron": return "SFGPU------F";
      case "regiment": case "group": return "SFGPU------G";
      case "brigade": return "SFGPU------H";
      case "division": return "SFGPU------I";
      default: return "SFGPU-------";
    }
  }

  function msIcon(sidc, designation, cls, size) {
    const key = `${sidc}|${designation}|${cls}|${size}`;
    let icon = iconCache.get(key);
    if (icon) return icon;
    let html = "", w = 30, h = 30, ax = 15, ay = 15;
    try {
      const sym = new ms.Symbol(sidc, { size: size, uniqueDesignation: designation });
      html = sym.asSVG();
      const sz = sym.getSize(), anchor = sym.getAnchor();
      w = Math.ceil(sz.width); h = Math.ceil(sz.height); ax = anchor.x; ay = anchor.y;
    } catch (e) {
      html = `<svg width="20" height="20"><rect x="1" y="1" width="18" height="18" fill="#80e0ff" stroke="#000"/></svg>`;
      w = h = 20; ax = ay = 10;
    }
    icon = L.divIcon({ className: cls, html, iconSize: [w, h], iconAnchor: [ax, ay] });
    if (iconCache.size > 2000) iconCache.clear();
    iconCache.set(key, icon);
    return icon;
  }

  function isHl(kind, id) { return highlighted.some((h) => h.kind === kind && h.id === id); }

  function updatePositions(pos, full) {
    if (!pos || !map) return;
    if (full) {
      for (const id of Array.from(unitMarkers.keys())) if (!(id in pos)) {
        map.removeLayer(unitMarkers.get(id)); unitMarkers.delete(id); delete S.positions[id];
      }
    }
    for (const [id, ll] of Object.entries(pos)) {
      let m = unitMarkers.get(id);
      if (!Array.isArray(ll) || ll.length < 2 || ll[0] === null) {
        if (m) { map.removeLayer(m); unitMarkers.delete(id); }
        delete S.positions[id];
        continue;
      }
      S.positions[id] = ll;
      const latlng = [ll[1], ll[0]];
      if (!m) {
        const cls = "unit-icon" + (isHl("unit", id) ? " hl" : "");
        m = L.marker(latlng, { icon: msIcon(sidcFor(id), id, cls, 20), pane: "units", title: unitTitle(id),
          keyboard: false });
        m.on("click", () => selectUnit(id));
        unitMarkers.set(id, m);
        if (unitVisible(id)) m.addTo(map);
      } else {
        m.setLatLng(latlng);
      }
    }
  }

  // Unit positions come per unit (the centroid of its subtree), for every echelon: the map
  // shows the upper echelons at the overlay's zoom and one more echelon per zoom level in.
  let baseZoom = null;
  function unitDepth(id) {
    let d = 0, u = S.units[id];
    const seen = new Set();
    while (u && u.parent && u.parent in S.units && !seen.has(u.parent) && d < 20) {
      seen.add(u.parent); d++; u = S.units[u.parent];
    }
    return d;
  }
  function unitVisible(id) {
    if (isHl("unit", id) || !map || baseZoom === null) return true;
    return unitDepth(id) <= 2 + Math.max(0, Math.floor((map.getZoom() - baseZoom - 0.5) / 1.5 + 0.01));
  }
  function declutter() {
    for (const [id, m] of unitMarkers) {
      const v = unitVisible(id), on = map.hasLayer(m);
      if (v && !on) m.addTo(map); else if (!v && on) map.removeLayer(m);
    }
  }

  function unitTitle(id) {
    const u = S.units[id];
    if (!u) return id;
    return `${id} ${u.name || ""}${u.mission ? " — " + u.mission : ""}`;
  }

  function updateTracks(tr, full) {
    if (!tr || !map) return;
    if (full) {
      for (const id of Array.from(trackMarkers.keys())) if (!(id in tr)) {
        map.removeLayer(trackMarkers.get(id)); trackMarkers.delete(id); delete S.tracks[id];
      }
    }
    for (const [id, v] of Object.entries(tr)) {
      let m = trackMarkers.get(id);
      const gone = !Array.isArray(v) || v.length < 2 || v[0] === null || (v.length > 2 && v[2] !== null && Number(v[2]) <= 0);
      if (gone) {
        if (m) { map.removeLayer(m); trackMarkers.delete(id); }
        delete S.tracks[id];
        continue;
      }
      const prev = S.tracks[id];
      S.tracks[id] = v;
      const strength = v.length > 2 && v[2] !== null ? String(v[2]) : "";
      const latlng = [v[1], v[0]];
      const cls = "track-icon" + (isHl("track", id) ? " hl" : "");
      if (!m) {
        m = L.marker(latlng, { icon: msIcon("SHGPU-------", strength, cls, 18), pane: "units",
          title: `${id} (strength ${strength || "?"})`, keyboard: false });
        m.addTo(map);
        trackMarkers.set(id, m);
      } else {
        m.setLatLng(latlng);
        if (!prev || String(prev[2]) !== strength) {
          m.setIcon(msIcon("SHGPU-------", strength, cls, 18));
          m.options.title = `${id} (strength ${strength || "?"})`;
        }
      }
    }
  }

  function refreshMarkerIcon(kind, id) {
    if (kind === "unit") {
      const m = unitMarkers.get(id);
      if (m) m.setIcon(msIcon(sidcFor(id), id, "unit-icon" + (isHl("unit", id) ? " hl" : ""), 20));
    } else if (kind === "track") {
      const m = trackMarkers.get(id), v = S.tracks[id];
      if (m && v) m.setIcon(msIcon("SHGPU-------", v.length > 2 && v[2] !== null ? String(v[2]) : "",
        "track-icon" + (isHl("track", id) ? " hl" : ""), 18));
    }
  }

  function clearHighlight() {
    const old = highlighted;
    highlighted = [];
    for (const h of old) {
      if (h.kind === "overlay") {
        const o = overlayById.get(h.id);
        if (o && o.layer.setStyle) o.layer.setStyle(o.style);
      } else refreshMarkerIcon(h.kind, h.id);
    }
    if (old.length && map) declutter();
  }

  /** Every string in the alert (subjects, details values, nested) that names a unit, a track
   * or an overlay feature. */
  function alertSubjects(a) {
    const found = new Map();
    const visit = (v, depth) => {
      if (depth > 4 || v === null || v === undefined) return;
      if (typeof v === "string") {
        if (overlayById.has(v)) found.set("overlay:" + v, { kind: "overlay", id: v });
        if (v in S.units || unitMarkers.has(v)) found.set("unit:" + v, { kind: "unit", id: v });
        if (trackMarkers.has(v)) found.set("track:" + v, { kind: "track", id: v });
      } else if (Array.isArray(v)) {
        for (const x of v) visit(x, depth + 1);
      } else if (typeof v === "object") {
        for (const [k, x] of Object.entries(v)) if (k !== "id" && k !== "repeat_of") visit(x, depth + 1);
      }
    };
    visit(a.subjects, 0);
    visit(a.details, 0);
    return Array.from(found.values());
  }

  function highlightAlert(a) {
    if (!map) return;
    clearHighlight();
    highlighted = alertSubjects(a);
    let bounds = null;
    const extend = (b) => { if (!b) return; bounds = bounds ? bounds.extend(b) : L.latLngBounds(b, b); };
    for (const h of highlighted) {
      if (h.kind === "overlay") {
        const o = overlayById.get(h.id);
        if (o.layer.setStyle) o.layer.setStyle(Object.assign({}, o.style, HL_STYLE, o.style.radius ? { radius: o.style.radius + 3 } : {}));
        if (o.layer.bringToFront) o.layer.bringToFront();
        if (o.layer.getBounds) { const b = o.layer.getBounds(); if (b.isValid()) { extend(b.getSouthWest()); extend(b.getNorthEast()); } }
        else if (o.layer.getLatLng) extend(o.layer.getLatLng());
      } else {
        refreshMarkerIcon(h.kind, h.id);
        const m = (h.kind === "unit" ? unitMarkers : trackMarkers).get(h.id);
        if (m && !map.hasLayer(m)) m.addTo(map);
        if (m) extend(m.getLatLng());
      }
    }
    if (a.details && typeof a.details.lon === "number" && typeof a.details.lat === "number")
      extend(L.latLng(a.details.lat, a.details.lon));
    if (bounds) map.fitBounds(bounds.pad(0.3), { maxZoom: 15, animate: false });
  }

  function selectUnit(id) {
    const m = unitMarkers.get(id);
    if (m && map) map.panTo(m.getLatLng());
    const row = document.querySelector(`#taskorg [data-unit="${cssEsc(id)}"]`);
    if (row) row.scrollIntoView({ block: "nearest" });
  }

  // ---------------------------------------------------------------- alerts
  const panes = {};       // priority -> {ul, count}
  let pending = [];       // alerts received, not yet rendered
  let flushScheduled = false;

  function passes(a) { return S.filter === "all" || a.owner === S.filter; }

  function paneOf(a) { return PRIORITIES.includes(a.priority) ? a.priority : "routine"; }

  function alertRow(a, fresh) {
    const d = a.details || {};
    const li = el("li", "alert" + (d.silenced ? " silenced" : "") + (fresh ? " new" : ""));
    const id = alertId(a);
    li.dataset.id = id;
    li.dataset.type = a.type || "";
    li.dataset.owner = a.owner || "";
    li.dataset.priority = a.priority || "";
    li.dataset.t = String(a.t);
    if (typeof d.repeat_of === "string") li.dataset.repeatOf = d.repeat_of;
    if (S.selected && alertId(S.selected) === id) li.classList.add("selected");
    const head = el("span", "a-head");
    head.appendChild(el("span", "a-t", hms(a.t)));
    head.appendChild(el("span", "a-owner", a.owner));
    head.appendChild(el("span", "a-type", a.type));
    head.appendChild(el("span", "a-cat", a.category));
    if (d.repeat_of || d.repeats) head.appendChild(el("span", "badge repeat", `repeat${d.repeats ? " " + d.repeats : ""}`));
    else if (d.repeat === true) head.appendChild(el("span", "badge repeat", "update"));
    if (d.escalated || d.escalated_from) head.appendChild(el("span", "badge escalated",
      "escalated" + (d.escalated_from ? " from " + d.escalated_from : "")));
    if (d.silenced) head.appendChild(el("span", "badge silenced", "silenced"));
    if (S.acked.has(id)) head.appendChild(el("span", "badge acked", "acked"));
    li.appendChild(head);
    li.appendChild(el("span", "a-msg", a.message));
    li.title = `${id} — ${a.priority}`;
    return li;
  }

  function addAlerts(list, live) {
    for (const a of list) {
      if (!a || typeof a !== "object") continue;
      const id = alertId(a);
      if (S.ids.has(id)) continue;
      S.ids.add(id);
      S.byId.set(id, a);
      S.alerts.push(a);
      window.__alertsSeen++;
      if (a.type && !S.types.has(a.type)) { S.types.add(a.type); addOption($("alert-types"), a.type); }
      const cff = a.details && (a.details.cff || a.details.call_for_fire);
      if (typeof cff === "string" && !S.cffs.has(cff)) { S.cffs.add(cff); addOption($("cff-ids"), cff); }
      pending.push(a);
    }
    if (S.alerts.length > MODEL_CAP) {
      const drop = S.alerts.splice(0, S.alerts.length - MODEL_CAP);
      for (const a of drop) S.byId.delete(alertId(a));   // ids stay in S.ids: no re-adding
    }
    $("seen").textContent = `${window.__alertsSeen} alerts`;
    scheduleFlush(live);
  }

  function addOption(datalist, value) {
    const o = document.createElement("option"); o.value = value; datalist.appendChild(o);
  }

  function scheduleFlush() {
    if (flushScheduled) return;
    flushScheduled = true;
    // requestAnimationFrame batches a burst into one DOM update; the timer covers a hidden
    // tab (no frames) so alerts are never held back for long.
    let done = false;
    const run = () => { if (done) return; done = true; flushScheduled = false; flush(); };
    requestAnimationFrame(run);
    setTimeout(run, 200);
  }

  function flush() {
    if (!pending.length) return;
    const batch = pending; pending = [];
    const byPane = { flash: [], immediate: [], priority: [], routine: [] };
    for (const a of batch) if (passes(a)) byPane[paneOf(a)].push(a);
    for (const p of PRIORITIES) {
      const list = byPane[p];
      if (!list.length) continue;
      const pane = panes[p];
      pane.count += list.length;
      // newest first: sort the batch by time (stable), newest on top
      list.sort((x, y) => (Number(y.t) || 0) - (Number(x.t) || 0));
      const frag = document.createDocumentFragment();
      const n = Math.min(list.length, PANE_CAP);
      for (let i = 0; i < n; i++) frag.appendChild(alertRow(list[i], true));
      pane.ul.insertBefore(frag, pane.ul.firstChild);
      while (pane.ul.childElementCount > PANE_CAP) pane.ul.removeChild(pane.ul.lastElementChild);
      updatePaneCount(p);
    }
    const now = performance.timeOrigin + performance.now();
    const log = window.__renderLog;
    for (const a of batch) {   // arrival order
      if (!passes(a)) continue;
      if (log.length >= RENDER_LOG_CAP) break;
      const d = a.details || {};
      log.push({ id: alertId(a), t_alert: a.t, rendered_ms: now, owner: a.owner, type: a.type,
                 priority: a.priority, message: a.message, repeat_of: d.repeat_of || null,
                 escalated_from: d.escalated_from || null });
    }
    scheduleCounts();
  }

  function updatePaneCount(p) {
    const pane = panes[p];
    const shown = pane.ul.childElementCount;
    $("count-" + p).textContent = pane.count > shown ? `${pane.count} (newest ${shown} shown)` : String(pane.count);
  }

  function rerenderPanes() {
    pending = [];
    flushScheduled = false;
    for (const p of PRIORITIES) {
      const pane = panes[p];
      pane.ul.textContent = "";
      pane.count = 0;
    }
    const byPane = { flash: [], immediate: [], priority: [], routine: [] };
    for (const a of S.alerts) if (passes(a)) byPane[paneOf(a)].push(a);
    for (const p of PRIORITIES) {
      const list = byPane[p], pane = panes[p];
      pane.count = list.length;
      const ordered = list.slice().sort((x, y) => (Number(y.t) || 0) - (Number(x.t) || 0));
      const frag = document.createDocumentFragment();
      for (let i = 0; i < Math.min(ordered.length, PANE_CAP); i++) frag.appendChild(alertRow(ordered[i], false));
      pane.ul.appendChild(frag);
      updatePaneCount(p);
    }
  }

  function showDetails(a) {
    S.selected = a;
    const id = alertId(a);
    document.querySelectorAll("li.alert.selected").forEach((x) => x.classList.remove("selected"));
    document.querySelectorAll(`li.alert[data-id="${cssEsc(id)}"]`).forEach((x) => x.classList.add("selected"));
    const box = $("details");
    box.textContent = "";
    const dl = el("dl");
    const row = (k, v, cls) => { dl.appendChild(el("dt", null, k)); dl.appendChild(el("dd", cls || null, v)); };
    row("id", id);
    row("time", `${hms(a.t)} (t=${a.t})`);
    row("owner", unitLabel(a.owner));
    row("priority", a.priority, "prio-" + a.priority);
    row("type", a.type);
    row("category", a.category);
    row("subjects", (a.subjects || []).join(", "));
    row("message", a.message);
    const d = a.details || {};
    for (const [k, v] of Object.entries(d)) if (k !== "id") row(k, fmt(v));
    for (const [k, v] of Object.entries(a)) {
      if (["t", "owner", "type", "category", "priority", "subjects", "message", "details", "__lid"].includes(k)) continue;
      row(k, fmt(v));
    }
    box.appendChild(dl);
    const ack = $("ack-btn");
    ack.disabled = false;
    ack.dataset.alert = id;
    ack.dataset.unit = a.owner || "";
    if (d.silenced) box.appendChild(el("p", "muted", `silenced by ${d.silenced}`));
    // an alert that asks for a decision: one button per option, the recommended one first
    const dec = d.decision;
    if (dec && Array.isArray(dec.options)) {
      const p = el("p", "decision", "Decide: ");
      const opts = [...dec.options].sort((x, y) => (y === dec.recommended) - (x === dec.recommended));
      for (const o of opts) {
        const b = el("button", o === dec.recommended ? "decide recommended" : "decide", o);
        b.type = "button";
        b.dataset.option = o;
        b.addEventListener("click", () => post("decide", { unit: a.owner || "", alert: id, option: o }).then((j) => {
          if (j && j.ok !== false) p.appendChild(el("span", "badge acked", `decided: ${o}`));
        }));
        p.appendChild(b);
      }
      box.appendChild(p);
    }
    // prefill the silence form with this alert's type and subjects
    $("silence-type").value = a.type || "";
    $("silence-subject").value = (a.subjects || []).join(", ");
    const cff = d.cff || d.call_for_fire;
    if (typeof cff === "string") $("cff-id").value = cff;
    highlightAlert(a);
  }

  function unitLabel(id) {
    const u = S.units[id];
    return u && u.name ? `${id} (${u.name})` : String(id);
  }

  // ---------------------------------------------------------------- counts (Fig. 7)
  let countsScheduled = false;
  function scheduleCounts() {
    if (countsScheduled) return;
    countsScheduled = true;
    setTimeout(() => { countsScheduled = false; renderCounts(); }, 250);
  }

  function unitOrder() {
    const order = [];
    const kids = {};
    const roots = [];
    for (const [id, u] of Object.entries(S.units)) {
      const p = u && u.parent;
      if (p && p in S.units) (kids[p] = kids[p] || []).push(id); else roots.push(id);
    }
    const walk = (id, depth) => { order.push([id, depth]); for (const c of kids[id] || []) walk(c, depth + 1); };
    for (const r of roots) walk(r, 0);
    return { order, kids, roots };
  }

  function renderCounts() {
    const table = $("counts");
    const owners = [];
    const ord = unitOrder().order.map((x) => x[0]);
    for (const u of ord) if (S.counts[u] && Object.keys(S.counts[u]).length) owners.push(u);
    for (const u of Object.keys(S.counts)) if (!owners.includes(u) && Object.keys(S.counts[u] || {}).length) owners.push(u);
    const types = new Set();
    for (const u of owners) for (const t of Object.keys(S.counts[u])) types.add(t);
    const typeList = Array.from(types).sort();
    const thead = table.tHead, tbody = table.tBodies[0];
    thead.textContent = ""; tbody.textContent = "";
    const hr = el("tr");
    hr.appendChild(el("th", null, "alert type"));
    for (const u of owners) {
      const th = el("th", null, u);
      th.title = unitLabel(u);
      th.dataset.owner = u;
      hr.appendChild(th);
    }
    thead.appendChild(hr);
    const frag = document.createDocumentFragment();
    const totals = owners.map(() => 0);
    for (const t of typeList) {
      const tr = el("tr");
      tr.dataset.type = t;
      tr.appendChild(el("td", null, t));
      owners.forEach((u, i) => {
        const n = Number(S.counts[u][t] || 0);
        totals[i] += n;
        const td = el("td", n ? null : "zero", String(n));
        td.dataset.owner = u;
        tr.appendChild(td);
      });
      frag.appendChild(tr);
    }
    const tot = el("tr", "total");
    tot.appendChild(el("td", null, "total"));
    totals.forEach((n, i) => { const td = el("td", null, String(n)); td.dataset.owner = owners[i]; tot.appendChild(td); });
    frag.appendChild(tot);
    // Fig. 7 also gives the flash alerts of each echelon: counted from the alerts seen here
    const flash = owners.map((u) => 0);
    const idx = new Map(owners.map((u, i) => [u, i]));
    for (const a of S.alerts) if (a.priority === "flash" && idx.has(a.owner)) flash[idx.get(a.owner)]++;
    const fl = el("tr", "total");
    fl.appendChild(el("td", null, "of them flash (seen)"));
    flash.forEach((n) => fl.appendChild(el("td", n ? null : "zero", String(n))));
    frag.appendChild(fl);
    tbody.appendChild(frag);
  }

  function mergeCounts(c) {
    if (!c || typeof c !== "object") return;
    for (const [owner, byType] of Object.entries(c)) {
      if (byType && typeof byType === "object") S.counts[owner] = Object.assign({}, byType);
    }
    scheduleCounts();
  }

  // ---------------------------------------------------------------- task organization
  function renderTaskorg() {
    const root = $("taskorg");
    root.textContent = "";
    const { kids, roots } = unitOrder();
    const build = (id) => {
      const li = el("li");
      li.dataset.unit = id;
      const row = el("div", "u-row");
      row.appendChild(el("span", "u-id", id));
      const u = S.units[id] || {};
      row.appendChild(el("span", "u-name", u.name || ""));
      row.appendChild(el("span", "u-mission", u.mission ? `${u.mission}${u.mission_type ? " (" + u.mission_type + ")" : ""}` : "—"));
      const st = el("span", "state " + (u.state || "none"), u.state || "");
      row.appendChild(st);
      row.addEventListener("click", (ev) => { ev.stopPropagation(); selectUnit(id); });
      li.appendChild(row);
      if (kids[id]) {
        const ul = el("ul");
        for (const c of kids[id]) ul.appendChild(build(c));
        li.appendChild(ul);
      }
      return li;
    };
    const frag = document.createDocumentFragment();
    for (const r of roots) frag.appendChild(build(r));
    root.appendChild(frag);
  }

  function updateTaskorgRow(id) {
    const li = document.querySelector(`#taskorg li[data-unit="${cssEsc(id)}"]`);
    if (!li) return false;
    const u = S.units[id] || {};
    const row = li.firstElementChild;
    row.querySelector(".u-mission").textContent = u.mission ? `${u.mission}${u.mission_type ? " (" + u.mission_type + ")" : ""}` : "—";
    const st = row.querySelector(".state");
    st.className = "state " + (u.state || "none");
    st.textContent = u.state || "";
    return true;
  }

  function mergeMissions(m) {
    if (!m || typeof m !== "object") return;
    let rebuild = false;
    for (const [id, v] of Object.entries(m)) {
      if (!v || typeof v !== "object") continue;
      const known = id in S.units;
      S.units[id] = Object.assign(S.units[id] || {}, v);
      if (!known || !updateTaskorgRow(id)) rebuild = true;
      const mk = unitMarkers.get(id);
      if (mk) mk.options.title = unitTitle(id);
    }
    if (rebuild) { renderTaskorg(); fillUnitSelect(); }
    fillMissions();
  }

  // ---------------------------------------------------------------- selects
  function fillUnitSelect() {
    const sel = $("unit-select");
    const cur = S.filter;
    sel.textContent = "";
    const all = el("option", null, "all"); all.value = "all"; sel.appendChild(all);
    for (const [id, depth] of unitOrder().order) {
      const u = S.units[id] || {};
      const o = el("option", null, `${"\u00a0\u00a0".repeat(depth)}${id}${u.name ? " — " + u.name : ""}`);
      o.value = id;
      sel.appendChild(o);
    }
    sel.value = cur;
    if (sel.value !== cur) { sel.value = "all"; }
  }

  function fillMissions() {
    const sel = $("confirm-mission");
    const cur = sel.value;
    const seen = new Set();
    const opts = [];
    for (const [id] of unitOrder().order) {
      const u = S.units[id] || {};
      const ms_ = [];
      if (u.mission) ms_.push(u.mission);
      if (Array.isArray(u.missions)) for (const x of u.missions) ms_.push(typeof x === "string" ? x : x && x.id);
      for (const m of ms_) {
        if (!m || seen.has(m)) continue;
        seen.add(m);
        opts.push([m, `${m} — ${id}${u.state ? " (" + u.state + ")" : ""}`, id]);
      }
    }
    const sig = JSON.stringify(opts);
    if (sel.dataset.sig === sig) return;
    sel.dataset.sig = sig;
    sel.textContent = "";
    for (const [v, label, unit] of opts) {
      const o = el("option", null, label); o.value = v; o.dataset.unit = unit; sel.appendChild(o);
    }
    if (seen.has(cur)) sel.value = cur;
  }

  /** The unit whose execution assistant an action goes to: the unit chosen in #unit-select
   * when this console may act for it, else the console's own unit. */
  function actor() {
    const f = S.filter;
    if (f && f !== "all" && (!S.actors.length || S.actors.includes(f))) return f;
    return S.unit;
  }

  function updateActorLabel() { $("actor-label").textContent = actor() ? `for ${actor()}` : ""; }

  // ---------------------------------------------------------------- actions
  async function post(kind, body) {
    let text;
    try {
      const r = await fetch("/api/" + kind, { method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify(body) });
      let j = null;
      const raw = await r.text();
      try { j = JSON.parse(raw); } catch (e) { j = null; }
      const req = j && j.result && j.result.req;
      if (req) { reported.add(req); if (reported.size > 1000) reported.clear(); }
      if (r.ok && j && j.ok !== false) {
        const res = j.result;
        text = `${kind} ${body.unit || ""}: ok` + (res && typeof res === "object" && res.t !== undefined ? ` at ${hms(res.t)}` : "")
          + (res !== undefined ? " " + JSON.stringify(res) : "");
        setStatus(text, true);
        return j;
      }
      const err = j && (j.error || (j.result && j.result.error)) || raw || `HTTP ${r.status}`;
      setStatus(`${kind} ${body.unit || ""}: error: ${err}`, false);
      return j;
    } catch (e) {
      setStatus(`${kind}: request failed: ${e}`, false);
      return null;
    }
  }

  const splitList = (s) => String(s || "").split(/[,\s]+/).map((x) => x.trim()).filter(Boolean);

  function parseValue(s) {
    s = String(s).trim();
    if (s.startsWith("[") || s.includes(",")) {
      const parts = s.replace(/^\[|\]$/g, "").split(",").map((x) => x.trim()).filter(Boolean);
      return parts.map(Number);
    }
    if (s === "") return null;
    const n = Number(s);
    return Number.isNaN(n) ? s : n;
  }

  function wireActions() {
    $("ack-btn").addEventListener("click", () => {
      const b = $("ack-btn");
      if (!b.dataset.alert) return;
      const id = b.dataset.alert;
      post("ack", { unit: b.dataset.unit, alert: id }).then((j) => {
        if (j && j.ok !== false) {
          S.acked.add(id);
          document.querySelectorAll(`li.alert[data-id="${cssEsc(id)}"] .a-head`).forEach((h) => {
            if (!h.querySelector(".badge.acked")) h.appendChild(el("span", "badge acked", "acked"));
          });
        }
      });
    });
    $("silence-form").addEventListener("submit", (ev) => {
      ev.preventDefault();
      const forS = Number($("silence-for").value);
      post("silence", { unit: actor(), types: splitList($("silence-type").value),
        subjects: splitList($("silence-subject").value), areas: splitList($("silence-area").value),
        for_s: Number.isFinite(forS) ? forS : $("silence-for").value, comment: $("silence-comment").value || "" });
    });
    $("set-key").addEventListener("change", () => {
      $("set-key-other-label").hidden = $("set-key").value !== "__other__";
    });
    $("set-btn").addEventListener("click", () => {
      let key = $("set-key").value;
      if (key === "__other__") key = $("set-key-other").value.trim();
      post("set", { unit: actor(), key, value: parseValue($("set-value").value) });
    });
    $("confirm-btn").addEventListener("click", () => {
      post("confirm", { unit: actor(), mission: $("confirm-mission").value, phase: $("confirm-phase").value });
    });
    $("cff-confirm-btn").addEventListener("click", () => post("cff", { unit: actor(), cff: $("cff-id").value.trim(), action: "confirm" }));
    $("cff-cancel-btn").addEventListener("click", () => post("cff", { unit: actor(), cff: $("cff-id").value.trim(), action: "cancel" }));

    $("unit-select").addEventListener("change", () => {
      S.filter = $("unit-select").value;
      updateActorLabel();
      rerenderPanes();
    });
    // one listener for every alert row (rows come and go)
    for (const p of PRIORITIES) {
      panes[p].ul.addEventListener("click", (ev) => {
        const li = ev.target.closest("li.alert");
        if (!li) return;
        const a = S.byId.get(li.dataset.id);
        if (a) showDetails(a);
      });
    }
  }

  const reported = new Set();   // request ids whose answer the POST already put in #status
  /** The silences in force that this console made, each with a button that lifts it. */
  function renderSilences(list) {
    const ul = $("silences");
    ul.textContent = "";
    for (const v of Array.isArray(list) ? list : []) {
      if (!v || typeof v !== "object") continue;
      const what = [["types", v.types], ["subjects", v.subjects], ["areas", v.areas]]
        .filter(([, x]) => Array.isArray(x) && x.length).map(([k, x]) => `${k} ${x.join(", ")}`).join("; ");
      const li = el("li", "silence", `${v.unit}: ${what} until ${hms(v.until_t)}${v.comment ? " — " + v.comment : ""} `);
      li.dataset.id = v.id;
      const b = el("button", "lift", "Lift");
      b.type = "button";
      b.addEventListener("click", () => post("unsilence", { unit: v.unit, id: v.id }));
      li.appendChild(b);
      ul.appendChild(li);
    }
  }

  /** A reorganization: new parents, and the units this console now acts for. */
  function applyOrg(d) {
    if (!d || typeof d !== "object") return;
    for (const [id, parent] of Object.entries(d.parents || {})) {
      if (S.units[id]) S.units[id].parent = parent;
    }
    if (Array.isArray(d.actors)) S.actors = d.actors;
    renderTaskorg();
    fillUnitSelect();
    updateActorLabel();
  }

  function onResult(r) {
    if (!r || typeof r !== "object") return;
    const ok = r.ok !== false;
    const who = r.unit || r.owner || "";
    (r.req && reported.has(r.req) ? logStatus : setStatus)(`result ${r.kind || ""}${who ? " " + who : ""} ${r.req || ""}: ${ok ? "ok" : "error: " + (r.error || "")}`
      + (r.t !== undefined ? ` at ${hms(r.t)}` : ""), ok);
  }

  // ---------------------------------------------------------------- helpers
  function fmt(v) {
    if (v === null || v === undefined) return String(v);
    if (typeof v === "number") return Number.isInteger(v) ? String(v) : String(Math.round(v * 1000) / 1000);
    if (typeof v === "string") return v;
    if (Array.isArray(v) && v.every((x) => typeof x !== "object" || x === null)) return v.map(fmt).join(", ");
    return JSON.stringify(v);
  }
  function esc(s) {
    return String(s).replace(/[&<>"']/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c]));
  }
  function cssEsc(s) { return window.CSS && CSS.escape ? CSS.escape(s) : String(s).replace(/["\\]/g, "\\$&"); }

  function setClock(t) {
    if (typeof t !== "number") return;
    S.t = t;
    $("clock").textContent = hms(t);
  }

  // ---------------------------------------------------------------- startup
  function applyState(st) {
    S.scenario = st.scenario || "";
    S.unit = st.unit || null;
    S.units = st.units || {};
    S.actors = Array.isArray(st.actors) ? st.actors : [];
    renderSilences(st.silences);
    $("scenario").textContent = S.scenario;
    document.title = `console ${S.unit || ""} — ${S.scenario}`;
    if (S.filter === "all" && S.unit && !applyState.done) S.filter = S.unit;
    applyState.done = true;
    fillUnitSelect();
    $("unit-select").value = S.filter;
    updateActorLabel();
    renderTaskorg();
    fillMissions();
    if (st.overlay && !applyState.overlay) { loadOverlay(st.overlay); applyState.overlay = true; }
    updatePositions(st.positions || {}, true);
    updateTracks(st.tracks || {}, true);
    S.counts = {};
    mergeCounts(st.counts || {});
    setClock(st.t);
    const alerts = Array.isArray(st.alerts) ? st.alerts.slice() : [];
    alerts.sort((x, y) => (Number(x.t) || 0) - (Number(y.t) || 0));
    addAlerts(alerts, false);
  }

  const HANDLERS = {
    alert: (d) => { if (Array.isArray(d)) addAlerts(d, true); else addAlerts([d], true); },
    alerts: (d) => addAlerts(Array.isArray(d) ? d : [d], true),
    clock: (d) => {
      if (d && Array.isArray(d.ticks)) {
        const log = window.__ticks;
        for (const tw of d.ticks) {
          if (Array.isArray(tw) && typeof tw[0] === "number" && typeof tw[1] === "number"
              && (!log.length || tw[0] > log[log.length - 1][0])) log.push([tw[0], tw[1] * 1000]);
        }
        if (log.length > TICK_LOG_CAP) log.splice(0, log.length - TICK_LOG_CAP);
      }
      setClock(typeof d === "number" ? d : d && d.t);
    },
    tracks: (d) => updateTracks(d, true),     // the server sends every current track
    positions: (d) => updatePositions(d, true),
    missions: (d) => mergeMissions(d),
    counts: (d) => mergeCounts(d),
    result: (d) => onResult(d),
    org: (d) => applyOrg(d),
    silences: (d) => renderSilences(d),
  };

  let ready = false;
  let early = [];   // events that came before the snapshot

  function dispatch(type, raw) {
    let d;
    try { d = JSON.parse(raw); } catch (e) { console.warn("bad event data", type, e); return; }
    if (!ready) { early.push([type, d]); return; }
    try { HANDLERS[type](d); } catch (e) { console.error("event", type, e); }
  }

  async function loadState() {
    const r = await fetch("/api/state", { cache: "no-store" });
    if (!r.ok) throw new Error(`GET /api/state: HTTP ${r.status}`);
    return r.json();
  }

  function connect() {
    const es = new EventSource("/events");
    let hadError = false;
    for (const type of Object.keys(HANDLERS)) es.addEventListener(type, (ev) => dispatch(type, ev.data));
    es.onopen = () => {
      const c = $("conn"); c.textContent = "live"; c.className = "conn up";
      if (hadError) {   // reconnected: catch up on what was missed (alerts are deduplicated by id)
        hadError = false;
        loadState().then(applyState).catch((e) => setStatus(String(e), false));
      }
    };
    es.onerror = () => {
      hadError = true;
      const c = $("conn"); c.textContent = "reconnecting"; c.className = "conn down";
    };
    return es;
  }

  async function start() {
    for (const p of PRIORITIES) panes[p] = { ul: $("pane-" + p), count: 0 };
    initMap();
    wireActions();
    window.__console = { S, map, hms };
    // open the stream first so nothing emitted between the snapshot and the stream is lost
    connect();
    try {
      applyState(await loadState());
    } catch (e) {
      setStatus(String(e), false);
    }
    ready = true;
    const ev = early; early = [];
    for (const [type, d] of ev) { try { HANDLERS[type](d); } catch (e) { console.error("event", type, e); } }
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
  else start();
})();
