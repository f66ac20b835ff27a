/* saim-mesh commander's console: the page (docs/console.md section 3).
 * Plain JavaScript, no build step. Reads GET /api/state once, then live updates from the
 * server-sent events at /events (no polling); actions POST to /api/<kind>. */
(function () {
  "use strict";

  const PRIORITIES = ["flash", "immediate", "priority", "routine"];
  const PANE_CAP = 200;          // story rows drawn per pane (the newest); the counts stay exact
  const QUIET_CAP = 200;         // rows drawn in the quiet view
  const MODEL_CAP = 200000;      // alerts kept in memory
  const RENDER_LOG_CAP = 100000;
  const STATUS_LOG_CAP = 30;

  window.__renderLog = [];
  window.__noticeLog = [];       // one entry per re-notification or escalation received (kind, alert, rendered_ms...)
  window.__alertsSeen = 0;
  window.__firstPaintMs = null;  // ms from navigation start to the snapshot drawn
  window.__frames = [];          // one per drawing: [start ms since navigation, its duration ms, alerts it drew]
  window.__paint = {};           // the first paint's steps: ms since navigation start
  window.__eventMs = {};         // per event type: [events handled, ms spent handling them]
  // The mesh clock: [scenario t, wall ms the console heard the clock reach t], in order. An
  // alert raised at t is due on the mesh at the first step at or after t; its latency is
  // from that moment to the alert's row on screen (same machine, same clock).
  const TICK_LOG_CAP = 400000;
  window.__ticks = [];
  // render_ms: from the page receiving the alert (its event, or the snapshot) to its row drawn.
  window.__latencies = function () {
    const ticks = window.__ticks, out = [];
    for (const e of window.__renderLog) {
      let lo = 0, hi = ticks.length;   // first tick with t >= the alert's t
      while (lo < hi) { const mid = (lo + hi) >> 1; if (ticks[mid][0] < e.t_alert) lo = mid + 1; else hi = mid; }
      const due = lo < ticks.length ? ticks[lo][1] : null;
      out.push(Object.assign({}, e, { due_ms: due, latency_ms: due === null ? null : e.rendered_ms - due,
                                      render_ms: e.received_ms === null ? null : e.rendered_ms - e.received_ms }));
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
    stories: new Map(),         // story id -> {id, owner, type, alerts, newest, rank, seq, renotified, blink...}
    quiet: [],                  // silenced or inhibited alerts (marked by their EA), arrival order
    seq: 0,                     // activity counter: rows are ordered by it, newest first
    noticeKeys: new Set(),      // notices seen (dedupe between snapshot and stream)
    escalations: new Map(),     // original alert id -> its escalate notice
    silences: [], inhibits: [], // in force, made by this console
    flashBy: {},                // owner -> flash alerts seen
    selectedStory: null,
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

  // ---------------------------------------------------------------- alerts: stories
  // One row per story (details.story: the id of the first alert of the same type and
  // subjects; its VOA updates share it). A story sits in the pane of its most urgent
  // alert; rows are ordered by their last activity (a new alert or a re-notification),
  // newest first. Silenced and inhibited alerts (details.silenced, details.inhibited_by)
  // never enter a pane: they go to the quiet view, as do stories a silence or inhibition
  // rule of this console covers now. Every change is drawn once per animation frame.
  const panes = {};          // priority -> {ul, more, count}
  let pendingLog = [];       // alerts received since the last frame (the render log)
  let pendingNotices = [];   // notices received since the last frame (the notice log)
  // dirty.layout: every story placed again (the unit shown, a silence or rule changed, time
  // passed under one); otherwise only the stories in `moved` (a new alert, a re-notification:
  // to the top of their pane) and `repaint` (acknowledged, selected) are looked at.
  const dirty = { layout: false, quiet: false, escalations: false, counts: false, inhibits: false };
  const moved = new Set(), repaint = new Set();
  let hiddenList = [];       // stories a silence or rule of this console covers now, newest first
  let frameScheduled = false;
  let lastQuietLayout = 0;   // wall ms: silences and rules in force are looked at again as time passes

  const rankOf = (p) => { const i = PRIORITIES.indexOf(p); return i < 0 ? 3 : i; };
  const urgent = (a) => a && (a.priority === "flash" || a.priority === "immediate");
  function isQuiet(a) { const d = a.details || {}; return !!(d.silenced || d.inhibited_by); }
  function storyOf(a) { const d = (a && a.details) || {}; return typeof d.story === "string" && d.story ? d.story : alertId(a); }
  function passesOwner(owner) { return S.filter === "all" || owner === S.filter; }
  function passes(a) { return passesOwner(a.owner); }

  function addAlerts(list) {
    const recv = performance.timeOrigin + performance.now();
    for (const a of list) {
      if (!a || typeof a !== "object") continue;
      if (!a.__recv) a.__recv = recv;
      const id = alertId(a);
      if (S.ids.has(id)) continue;
      S.ids.add(id);
      S.byId.set(id, a);
      S.alerts.push(a);
      window.__alertsSeen++;
      if (a.type && !S.types.has(a.type)) { S.types.add(a.type); addOption($("alert-types"), a.type); }
      const cff = a.details && (a.details.cff || a.details.call_for_fire);
      if (typeof cff === "string" && !S.cffs.has(cff)) { S.cffs.add(cff); addOption($("cff-ids"), cff); }
      if (a.priority === "flash") S.flashBy[a.owner] = (S.flashBy[a.owner] || 0) + 1;
      if (isQuiet(a)) {
        a.__seq = ++S.seq;
        S.quiet.push(a);
        dirty.quiet = true;
      } else {
        moved.add(addToStory(a));
      }
      pendingLog.push(a);
    }
    if (S.alerts.length > MODEL_CAP) {
      const drop = S.alerts.splice(0, S.alerts.length - MODEL_CAP);
      for (const a of drop) S.byId.delete(alertId(a));   // ids stay in S.ids: no re-adding
    }
    if (S.quiet.length > MODEL_CAP / 10) S.quiet.splice(0, S.quiet.length - MODEL_CAP / 10);
    dirty.counts = true;
    scheduleFrame();
  }

  function addOption(datalist, value) {
    const o = document.createElement("option"); o.value = value; datalist.appendChild(o);
  }

  function addToStory(a) {
    const sid = storyOf(a);
    let st = S.stories.get(sid);
    if (!st) {
      st = { id: sid, owner: a.owner || "", type: a.type || "", alerts: [], newest: null, rank: 3, seq: 0,
             renotified: 0, blink: false, el: null, qel: null, dirty: true, quietBy: null, where: null };
      S.stories.set(sid, st);
    }
    st.alerts.push(a);
    if (!st.newest || (Number(a.t) || 0) >= (Number(st.newest.t) || 0)) st.newest = a;
    st.rank = Math.min(st.rank, rankOf(a.priority));
    st.seq = ++S.seq;
    st.dirty = true;
    return st;
  }

  /** A re-notification (the story's row goes to the top of its pane and blinks until
   * acknowledged) or an escalation (listed in #escalations when it is for this console). */
  function addNotices(list) {
    for (const n of list) {
      if (!n || typeof n !== "object" || typeof n.alert !== "string") continue;
      const key = `${n.kind}|${n.alert}|${n.count}|${n.to}`;
      if (S.noticeKeys.has(key)) continue;
      S.noticeKeys.add(key);
      pendingNotices.push(n);
      if (n.kind === "renotify") {
        const st = S.stories.get(typeof n.story === "string" ? n.story : "")
          || S.stories.get(storyOf(S.byId.get(n.alert)));
        if (!st || S.acked.has(n.alert)) continue;
        st.renotified = Math.max(st.renotified, Number(n.count) || 1);
        st.blink = true;
        st.seq = ++S.seq;
        st.dirty = true;
        moved.add(st);
      } else if (n.kind === "escalate") {
        S.escalations.set(n.alert, n);
        dirty.escalations = true;
        const st = S.stories.get(typeof n.story === "string" ? n.story : "");
        if (st) { st.dirty = true; repaint.add(st); }   // its row says "escalated"
      }
    }
    if (S.noticeKeys.size > MODEL_CAP) S.noticeKeys.clear();
    scheduleFrame();
  }

  function storyAcked(st) {
    let any = false;
    for (const a of st.alerts) {
      if (!urgent(a)) continue;
      any = true;
      if (!S.acked.has(alertId(a))) return false;
    }
    return any;
  }

  function markAcked(id) {
    if (typeof id !== "string" || S.acked.has(id)) return;
    S.acked.add(id);
    const a = S.byId.get(id);
    const st = a ? S.stories.get(storyOf(a)) : null;
    if (st) {
      st.blink = false;   // the commander answered: no more blinking
      st.dirty = true;
      repaint.add(st);
    }
    if (S.escalations.has(id)) dirty.escalations = true;
    scheduleFrame();
  }

  // -- what a silence or an inhibition rule of this console covers now (the EA marks the
  // alerts it raises under them; rows already shown leave the panes too)
  const inList = (list, v) => !Array.isArray(list) || !list.length || list.includes(v);
  const inAny = (list, vs) => !Array.isArray(list) || !list.length || (Array.isArray(vs) && vs.some((x) => list.includes(x)));
  function silenceCovers(s, a) {
    if (s.unit !== a.owner || !(Number(s.until_t) > S.t)) return false;
    return inList(s.types, a.type) && inAny(s.subjects, a.subjects) && inAny(s.areas, (a.details || {}).places);
  }
  function matcherCovers(m, a) {
    m = m || {};
    return inList(m.types, a.type) && inAny(m.subjects, a.subjects) && inList(m.priorities, a.priority)
      && inList(m.owners, a.owner);
  }
  function labels(a, k) {
    if (k === "subjects") return Array.isArray(a.subjects) ? a.subjects : [];
    if (k === "owner") return [a.owner];
    if (k === "category") return [a.category];
    const p = (a.details || {}).places;
    return Array.isArray(p) ? p : [];
  }
  function related(r, src, tgt) {
    return (r.equal || []).every((k) => { const y = labels(tgt, k); return labels(src, k).some((v) => y.includes(v)); });
  }
  /** The alerts that make rule r's source active now: raised since the rule was added
   * (as the EA counts them), within its window, by the rule's EA. */
  function ruleSources(r) {
    const out = [];
    const from = Math.max(Number(r.t) || 0, S.t - (Number(r.active_s) || Number(r.for_s) || 720));
    for (let i = S.alerts.length - 1; i >= 0; i--) {
      const a = S.alerts[i], t = Number(a.t) || 0;
      if (t < from - 600) break;   // arrival order is time order, give or take a tick
      if (t >= from && a.owner === r.unit && matcherCovers(r.source, a)) out.push(a);
    }
    return out;
  }
  function quietReason(st, srcs) {
    const a = st.newest;
    for (const s of S.silences) if (silenceCovers(s, a)) return `silence ${s.id} in force`;
    for (const r of S.inhibits) {
      if (r.unit !== a.owner || !matcherCovers(r.target, a)) continue;
      const src = (srcs.get(r) || []).find((x) => storyOf(x) !== st.id && related(r, x, a));
      if (src) return `inhibition rule ${r.id} in force (source ${alertId(src)})`;
    }
    return null;
  }

  /** Where a story goes now: its pane, "quiet" (covered by a silence or rule of ours) or
   * null (another unit's, not shown). */
  function place(st, srcs) {
    if (!passesOwner(st.owner)) return null;
    const why = S.silences.length + S.inhibits.length ? quietReason(st, srcs) : null;
    if (why !== st.quietBy) { st.quietBy = why; st.dirty = true; }
    return why ? "quiet" : PRIORITIES[st.rank];
  }

  function ruleSourcesAll() {
    const srcs = new Map();
    for (const r of S.inhibits) srcs.set(r, ruleSources(r));
    return srcs;
  }

  /** Every story placed again, each pane's list sorted newest activity first. */
  function layout() {
    const srcs = ruleSourcesAll();
    for (const p of PRIORITIES) panes[p].list = [];
    hiddenList = [];
    for (const st of S.stories.values()) {
      st.where = place(st, srcs);
      if (st.where === "quiet") hiddenList.push(st);
      else if (st.where) panes[st.where].list.push(st);
    }
    for (const p of PRIORITIES) panes[p].list.sort((x, y) => y.seq - x.seq);
    hiddenList.sort((x, y) => y.seq - x.seq);
    moved.clear();
  }

  /** The stories that moved since the last frame, taken out of where they were and put at
   * the top of where they go (their activity is newer than any other's). Returns the
   * panes that changed. */
  function move() {
    const changed = new Set();
    const srcs = S.inhibits.length ? ruleSourcesAll() : null;
    const front = { flash: [], immediate: [], priority: [], routine: [], quiet: [] };
    for (const st of moved) {
      if (st.where) {
        const list = st.where === "quiet" ? hiddenList : panes[st.where].list;
        const i = list.indexOf(st);
        if (i >= 0) list.splice(i, 1);
        changed.add(st.where);
      }
      st.where = place(st, srcs);
      if (st.where) { front[st.where].push(st); changed.add(st.where); }
    }
    moved.clear();
    for (const p of PRIORITIES) {
      if (!front[p].length) continue;
      front[p].sort((x, y) => y.seq - x.seq);
      panes[p].list = front[p].concat(panes[p].list);
    }
    if (front.quiet.length) hiddenList = front.quiet.sort((x, y) => y.seq - x.seq).concat(hiddenList);
    return changed;
  }

  function storyRow(st) {
    let li = st.el;
    if (!li) {
      li = st.el = el("li", "alert story new");
      li.dataset.story = st.id;
    } else if (!st.dirty) {
      return li;
    }
    const a = st.newest, id = alertId(a), n = st.alerts.length;
    li.dataset.id = id;
    li.dataset.type = a.type || "";
    li.dataset.owner = a.owner || "";
    li.dataset.priority = PRIORITIES[st.rank];
    li.dataset.t = String(a.t);
    li.dataset.count = String(n);
    if (st.renotified) li.dataset.renotified = String(st.renotified); else delete li.dataset.renotified;
    li.classList.toggle("renotified", st.blink);
    const acked = storyAcked(st);
    li.classList.toggle("acked", acked);
    li.classList.toggle("selected", S.selectedStory === st.id);
    li.textContent = "";
    const head = el("span", "a-head");
    head.appendChild(el("span", "a-t", hms(a.t)));
    head.appendChild(el("span", "a-owner", a.owner));
    head.appendChild(el("span", "a-type", a.type));
    head.appendChild(el("span", "a-cat", a.category));
    const c = el("span", "story-count" + (n === 1 ? " single" : ""), String(n));
    c.title = `${n} alert${n === 1 ? "" : "s"} in this story (the first ${st.id})`;
    head.appendChild(c);
    if (st.renotified) head.appendChild(el("span", "badge renotified", `told again ${st.renotified}`));
    if (S.escalations.has(id) || st.alerts.some((x) => S.escalations.has(alertId(x))))
      head.appendChild(el("span", "badge escalated", "escalated"));
    if (acked) head.appendChild(el("span", "badge acked", "acked"));
    li.appendChild(head);
    li.appendChild(el("span", "a-msg", a.message));
    li.title = `story ${st.id}: ${n} alert${n === 1 ? "" : "s"}, newest ${id} (${a.priority})`;
    st.dirty = false;
    return li;
  }

  function quietRow(why, a, st) {
    const li = el("li", "alert quiet");
    li.dataset.id = alertId(a);
    li.dataset.type = a.type || "";
    li.dataset.owner = a.owner || "";
    li.dataset.priority = a.priority || "";
    li.dataset.t = String(a.t);
    if (st) li.dataset.story = st.id;
    const head = el("span", "a-head");
    head.appendChild(el("span", "a-t", hms(a.t)));
    head.appendChild(el("span", "a-owner", a.owner));
    head.appendChild(el("span", "a-type", a.type));
    head.appendChild(el("span", "a-cat", a.priority));
    li.appendChild(head);
    li.appendChild(el("span", "a-msg", a.message));
    li.appendChild(el("span", "a-why", why));
    return li;
  }

  function quietWhy(a) {
    const d = a.details || {};
    if (d.silenced) return `silenced by ${d.silenced}`;
    const ib = d.inhibited_by;
    if (ib && typeof ib === "object") return `inhibited by rule ${ib.rule}${ib.source ? " (source " + ib.source + ")" : ""}`;
    return `inhibited by ${fmt(ib)}`;
  }

  /** Puts `nodes` in `ul` in this order, moving as few as it can. */
  function reconcile(ul, nodes) {
    let ref = ul.firstChild;
    for (const n of nodes) {
      if (n === ref) { ref = ref.nextSibling; continue; }
      ul.insertBefore(n, ref);
    }
    while (ref) { const next = ref.nextSibling; ul.removeChild(ref); ref = next; }
  }

  // A burst of events (a server batch) is drawn in one go, as soon as the page is free:
  // a posted message runs after the events already queued, before the next frame; the
  // animation frame and the timer cover a browser that delays either.
  const soon = new MessageChannel();
  let soonRun = null;
  soon.port1.onmessage = () => { if (soonRun) soonRun(); };
  function scheduleFrame() {
    if (frameScheduled) return;
    frameScheduled = true;
    let done = false;
    const run = () => { if (done) return; done = true; soonRun = null; frame(); };
    soonRun = run;
    soon.port2.postMessage(null);
    requestAnimationFrame(run);
    setTimeout(run, 200);
  }

  function frame() {
    frameScheduled = false;
    const t0 = performance.now(), nAlerts = pendingLog.length;
    if (dirty.layout || moved.size || repaint.size || dirty.quiet) drawPanes();
    if (dirty.escalations) { dirty.escalations = false; renderEscalations(); }
    if (dirty.inhibits) { dirty.inhibits = false; renderInhibits(); }
    if (dirty.counts) { dirty.counts = false; renderCounts(); }
    const now = performance.timeOrigin + performance.now();
    const log = window.__renderLog;
    for (const a of pendingLog) {   // arrival order
      if (!passes(a) || log.length >= RENDER_LOG_CAP) continue;
      const d = a.details || {};
      log.push({ id: alertId(a), t_alert: a.t, received_ms: a.__recv || null, rendered_ms: now, owner: a.owner, type: a.type,
                 priority: a.priority, message: a.message, story: storyOf(a), quiet: isQuiet(a),
                 repeat_of: d.repeat_of || null, escalated_from: d.escalated_from || null });
    }
    pendingLog = [];
    const nlog = window.__noticeLog;
    for (const n of pendingNotices) {
      if (nlog.length >= RENDER_LOG_CAP) break;
      nlog.push({ kind: n.kind, alert: n.alert, story: n.story, owner: n.owner, to: n.to, count: n.count,
                  t: n.t, received_ms: n.__recv || null, rendered_ms: now });
    }
    pendingNotices = [];
    $("seen").textContent = `${window.__alertsSeen} alerts, ${S.stories.size} stories`;
    const fl = window.__frames;
    if (fl.length < RENDER_LOG_CAP) fl.push([Math.round(t0), Math.round((performance.now() - t0) * 10) / 10, nAlerts]);
  }

  function drawPanes() {
    let changed;
    if (dirty.layout || (S.inhibits.length && moved.size)) {   // a rule's sources may have come or gone
      dirty.layout = false;
      lastQuietLayout = performance.now();
      layout();
      changed = new Set([...PRIORITIES, "quiet"]);
    } else {
      changed = move();
    }
    for (const st of repaint) if (st.el && st.el.isConnected) storyRow(st);
    repaint.clear();
    for (const p of PRIORITIES) {
      if (!changed.has(p)) continue;
      const pane = panes[p], list = pane.list;
      pane.count = list.length;
      const n = Math.min(list.length, PANE_CAP);
      const rows = new Array(n);
      for (let i = 0; i < n; i++) rows[i] = storyRow(list[i]);
      reconcile(pane.ul, rows);
      $("count-" + p).textContent = String(list.length);
      const more = $("more-" + p);
      more.hidden = list.length <= n;
      if (!more.hidden) more.textContent = `${list.length - n} more (the newest ${n} stories shown)`;
    }
    if (changed.has("quiet") || dirty.quiet) { dirty.quiet = false; drawQuiet(); }
  }

  function drawQuiet() {
    const hidden = hiddenList;
    // the quiet view: alerts the EA marked, and stories a silence or rule of ours covers now
    const items = [];
    for (let i = S.quiet.length - 1; i >= 0 && items.length < 4 * QUIET_CAP; i--) {
      const a = S.quiet[i];
      if (passes(a)) items.push([a.__seq, a, null]);
    }
    for (const st of hidden) items.push([st.seq, st.newest, st]);
    items.sort((x, y) => y[0] - x[0]);
    let total = hidden.length;
    for (const a of S.quiet) if (passes(a)) total++;
    const rows = [];
    for (const [, a, st] of items.slice(0, QUIET_CAP)) {
      if (st) {
        if (!st.qel || st.qel.dataset.why !== st.quietBy || st.qel.dataset.id !== alertId(a)) {
          st.qel = quietRow(st.quietBy, a, st);
          st.qel.dataset.why = st.quietBy;
        }
        rows.push(st.qel);
      } else {
        if (!a.__qel) a.__qel = quietRow(quietWhy(a), a, null);
        rows.push(a.__qel);
      }
    }
    reconcile($("pane-quiet"), rows);
    $("count-quiet").textContent = String(total);
    const more = $("more-quiet");
    more.hidden = total <= rows.length;
    if (!more.hidden) more.textContent = `${total - rows.length} more (the newest ${rows.length} shown)`;
    $("quiet-toggle").textContent = `Quiet (${total})`;
  }

  function rerenderPanes() {
    dirty.layout = dirty.quiet = dirty.escalations = dirty.counts = true;
    frame();
  }

  // ---------------------------------------------------------------- escalations
  /** Escalations from below for this console: the selected unit, or any unit it acts for. */
  function renderEscalations() {
    const ul = $("escalations");
    const mine = new Set(S.actors);
    if (S.unit) mine.add(S.unit);
    if (S.filter !== "all") mine.add(S.filter);
    const list = [];
    for (const n of S.escalations.values()) if (mine.has(n.to)) list.push(n);
    list.sort((x, y) => (Number(y.t) || 0) - (Number(x.t) || 0));
    const rows = [];
    let open = 0;
    for (const n of list.slice(0, 100)) {
      const acked = S.acked.has(n.alert);
      if (!acked) open++;
      const li = el("li", "escalation" + (acked ? " acked" : ""));
      li.dataset.alert = n.alert;
      li.dataset.owner = n.owner;
      li.dataset.to = n.to;
      li.appendChild(el("span", "e-text", `unacknowledged at ${n.owner}: ${n.message}`));
      li.appendChild(el("span", "muted", ` (${n.priority}, ${hms(n.due_t)}; to ${n.to} at ${hms(n.t)})`));
      const b = el("button", "show", acked ? "acked" : "Show");
      b.type = "button";
      b.dataset.alert = n.alert;
      li.appendChild(b);
      rows.push(li);
    }
    for (const n of list.slice(100)) if (!S.acked.has(n.alert)) open++;
    if (!rows.length) rows.push(el("li", "none", "none"));
    ul.textContent = "";
    const frag = document.createDocumentFragment();
    for (const r of rows) frag.appendChild(r);
    ul.appendChild(frag);
    $("count-escalations").textContent = String(open);
  }

  /** Shows alert `aid` (an escalated one may never have been drawn here: asked of the server). */
  async function selectAlert(aid) {
    let a = S.byId.get(aid);
    if (!a) {
      try {
        const r = await fetch("/api/alert?id=" + encodeURIComponent(aid), { cache: "no-store" });
        if (!r.ok) { setStatus(`alert ${aid}: ${(await r.json()).error || "HTTP " + r.status}`, false); return; }
        a = await r.json();
        addAlerts([a]);
        a = S.byId.get(aid) || a;
      } catch (e) {
        setStatus(`alert ${aid}: ${e}`, false);
        return;
      }
    }
    showDetails(a);
  }

  function showDetails(a) {
    S.selected = a;
    const id = alertId(a), sid = storyOf(a);
    const st = isQuiet(a) ? null : S.stories.get(sid);
    S.selectedStory = st ? st.id : null;
    document.querySelectorAll("li.alert.selected").forEach((x) => x.classList.remove("selected"));
    document.querySelectorAll(`li.alert[data-id="${cssEsc(id)}"]`).forEach((x) => x.classList.add("selected"));
    if (st && st.el) st.el.classList.add("selected");
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
      if (["t", "owner", "type", "category", "priority", "subjects", "message", "details"].includes(k) || k.startsWith("__")) continue;
      row(k, fmt(v));
    }
    box.appendChild(dl);
    const ack = $("ack-btn");
    ack.disabled = false;
    ack.dataset.alert = id;
    ack.dataset.unit = a.owner || "";
    ack.dataset.story = st ? st.id : "";
    if (isQuiet(a)) box.appendChild(el("p", "muted", quietWhy(a)));
    const esc = S.escalations.get(id);
    if (esc) box.appendChild(el("p", "escalated-note", `escalated to ${esc.to} at ${hms(esc.t)}: unacknowledged at ${esc.owner}`));
    if (st && st.renotified) box.appendChild(el("p", "muted", `told again ${st.renotified} time${st.renotified === 1 ? "" : "s"}`));
    // the story: every alert folded under the row, newest first (a click shows one)
    if (st && st.alerts.length > 1) {
      box.appendChild(el("p", "story-head", `story ${st.id}: ${st.alerts.length} alerts, newest first`));
      const ol = el("ol", "story-alerts");
      const all = st.alerts.slice().sort((x, y) => (Number(y.t) || 0) - (Number(x.t) || 0));
      for (const x of all.slice(0, 200)) {
        const li = el("li", alertId(x) === id ? "shown" : null, `${hms(x.t)} ${x.priority} ${alertId(x)}: ${x.message}`);
        li.dataset.id = alertId(x);
        li.addEventListener("click", () => showDetails(x));
        ol.appendChild(li);
      }
      box.appendChild(ol);
    }
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
          if (j && j.ok !== false) { p.appendChild(el("span", "badge acked", `decided: ${o}`)); markAcked(id); }
        }));
        p.appendChild(b);
      }
      box.appendChild(p);
    }
    // prefill the silence and inhibition forms with this alert's type and subjects
    $("silence-type").value = a.type || "";
    $("silence-subject").value = (a.subjects || []).join(", ");
    $("inhibit-target-type").value = a.type || "";
    const cff = d.cff || d.call_for_fire;
    if (typeof cff === "string") $("cff-id").value = cff;
    highlightAlert(a);
  }

  function unitLabel(id) {
    const u = S.units[id];
    return u && u.name ? `${id} (${u.name})` : String(id);
  }

  // ---------------------------------------------------------------- counts (Fig. 7)
  // Every alert the EAs logged, per owner and type (the server's counts: quiet ones count,
  // re-notifications do not), for the selected unit and the units under it (all: every
  // owner), drawn in the same frame as the panes.
  function unitOrder() {
    const order = [];
    const kids = {};
    const roots = [];
    for (const [id, u] of Object.entries(S.units)) {
      const p = u && u.parent;
      if (p && p in S.units && p !== id) (kids[p] = kids[p] || []).push(id); else roots.push(id);
    }
    const seen = new Set();
    const walk = (id, depth) => {
      if (seen.has(id)) return;
      seen.add(id);
      order.push([id, depth]);
      for (const c of kids[id] || []) walk(c, depth + 1);
    };
    for (const r of roots) walk(r, 0);
    return { order, kids, roots };
  }

  function subtree(unit, kids) {
    const out = [], stack = [unit], seen = new Set();
    while (stack.length) {
      const u = stack.pop();
      if (seen.has(u)) continue;
      seen.add(u);
      out.push(u);
      for (const c of (kids[u] || []).slice().reverse()) stack.push(c);
    }
    return out;
  }

  function countOwners() {
    const { order, kids } = unitOrder();
    const has = (u) => S.counts[u] && Object.keys(S.counts[u]).length > 0;
    if (S.filter !== "all" && S.filter in S.units) {
      const sub = subtree(S.filter, kids);
      return [S.filter, ...sub.slice(1).filter(has)];   // the selected unit's column from the start
    }
    const owners = order.map((x) => x[0]).filter(has);
    for (const u of Object.keys(S.counts)) if (!owners.includes(u) && has(u)) owners.push(u);
    return owners;
  }

  let countsShape = "", countCells = new Map();   // the table's owners and types; "owner|type" -> td
  function renderCounts() {
    const table = $("counts");
    const owners = countOwners();
    const types = new Set();
    for (const u of owners) for (const t of Object.keys(S.counts[u] || {})) types.add(t);
    const typeList = Array.from(types).sort();
    const shape = JSON.stringify([owners, typeList]);
    const cell = (u, t) => Number((S.counts[u] || {})[t] || 0);
    const set = (td, n) => {
      const v = String(n);
      if (td.textContent !== v) { td.textContent = v; td.classList.toggle("zero", !n); }
    };
    if (shape === countsShape) {   // the same rows and columns: only numbers change
      const totals = owners.map(() => 0);
      owners.forEach((u, i) => {
        for (const t of typeList) { const n = cell(u, t); totals[i] += n; set(countCells.get(u + "|" + t), n); }
        set(countCells.get(u + "|total"), totals[i]);
        set(countCells.get(u + "|flash"), S.flashBy[u] || 0);
      });
      return;
    }
    countsShape = shape;
    countCells = new Map();
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
        const n = cell(u, t);
        totals[i] += n;
        const td = el("td", n ? null : "zero", String(n));
        td.dataset.owner = u;
        countCells.set(u + "|" + t, td);
        tr.appendChild(td);
      });
      frag.appendChild(tr);
    }
    const tot = el("tr", "total");
    tot.appendChild(el("td", null, "total"));
    totals.forEach((n, i) => {
      const td = el("td", null, String(n));
      td.dataset.owner = owners[i];
      countCells.set(owners[i] + "|total", td);
      tot.appendChild(td);
    });
    frag.appendChild(tot);
    // Fig. 7 also gives the flash alerts of each echelon: counted from the alerts seen here
    const fl = el("tr", "total");
    fl.appendChild(el("td", null, "of them flash (seen)"));
    owners.forEach((u) => {
      const n = S.flashBy[u] || 0;
      const td = el("td", n ? null : "zero", String(n));
      countCells.set(u + "|flash", td);
      fl.appendChild(td);
    });
    frag.appendChild(fl);
    tbody.appendChild(frag);
  }

  function mergeCounts(c) {
    if (!c || typeof c !== "object") return;
    for (const [owner, byType] of Object.entries(c)) {
      if (byType && typeof byType === "object") S.counts[owner] = Object.assign({}, byType);
    }
    dirty.counts = true;
    scheduleFrame();
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
  /** POST /api/<kind>; the answer goes to #status (`quiet`: a success to the log only). */
  async function post(kind, body, quiet = false) {
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
        (quiet ? logStatus : setStatus)(text, true);
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
    $("ack-btn").addEventListener("click", async () => {
      const b = $("ack-btn");
      if (!b.dataset.alert) return;
      const id = b.dataset.alert, unit = b.dataset.unit;
      // the shown alert, and every other urgent alert of its story not yet acknowledged:
      // the commander answers the story, and its re-notifications stop
      const targets = [id];
      const st = b.dataset.story ? S.stories.get(b.dataset.story) : null;
      if (st) {
        for (const x of st.alerts) {
          const xid = alertId(x);
          if (xid !== id && urgent(x) && !S.acked.has(xid) && targets.length < 20) targets.push(xid);
        }
      }
      b.disabled = true;
      try {
        for (const t of targets) {   // the shown alert first; #status keeps its answer
          const j = await post("ack", { unit, alert: t }, t !== id);
          if (j && j.ok !== false) markAcked(t);
        }
      } finally {
        b.disabled = false;
      }
      if (S.selected) showDetails(S.selected);
    });
    $("silence-form").addEventListener("submit", (ev) => {
      ev.preventDefault();
      const forS = Number($("silence-for").value);
      post("silence", { unit: actor(), types: splitList($("silence-type").value),
        subjects: splitList($("silence-subject").value), areas: splitList($("silence-area").value),
        for_s: Number.isFinite(forS) ? forS : $("silence-for").value, comment: $("silence-comment").value || "" });
    });
    $("inhibit-form").addEventListener("submit", (ev) => {
      ev.preventDefault();
      const body = { unit: actor(), source: { types: splitList($("inhibit-source-type").value) },
        target: { types: splitList($("inhibit-target-type").value) },
        equal: $("inhibit-equal").value ? [$("inhibit-equal").value] : [],
        comment: $("inhibit-comment").value || "" };
      const rid = $("inhibit-id").value.trim();
      if (rid) body.id = rid;
      const f = $("inhibit-for").value.trim();
      if (f !== "") body.for_s = Number.isFinite(Number(f)) ? Number(f) : f;
      post("inhibit", body);
    });
    $("quiet-toggle").addEventListener("click", () => {
      const w = $("quiet-wrap");
      w.hidden = !w.hidden;
      $("quiet-toggle").setAttribute("aria-expanded", String(!w.hidden));
    });
    $("escalations").addEventListener("click", (ev) => {
      const b = ev.target.closest("button.show");
      if (b && b.dataset.alert) selectAlert(b.dataset.alert);
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
    $("order-btn").addEventListener("click", () => {
      const action = $("order-action").value, target = $("order-target").value.trim();
      const body = { unit: actor(), action, in_s: Number($("order-in").value) };
      if (action === "execute-plan") body.plan = target;
      if (action.endsWith("-mission")) body.mission = target;
      post("order", body);
    });
    $("cff-confirm-btn").addEventListener("click", () => post("cff", { unit: actor(), cff: $("cff-id").value.trim(), action: "confirm" }));
    $("cff-cancel-btn").addEventListener("click", () => post("cff", { unit: actor(), cff: $("cff-id").value.trim(), action: "cancel" }));

    $("unit-select").addEventListener("change", () => {
      S.filter = $("unit-select").value;
      updateActorLabel();
      rerenderPanes();
    });
    // one listener for every row (rows come and go): a story shows its newest alert
    for (const p of [...PRIORITIES, "quiet"]) {
      $("pane-" + p).addEventListener("click", (ev) => {
        const li = ev.target.closest("li.alert");
        if (!li) return;
        const st = li.dataset.story && p !== "quiet" ? S.stories.get(li.dataset.story) : null;
        const a = st ? st.newest : S.byId.get(li.dataset.id);
        if (a) showDetails(a);
      });
    }
  }

  const reported = new Set();   // request ids whose answer the POST already put in #status
  /** The silences in force that this console made, each with a button that lifts it; the
   * stories they cover leave the panes for the quiet view. */
  function renderSilences(list) {
    S.silences = (Array.isArray(list) ? list : []).filter((v) => v && typeof v === "object");
    const ul = $("silences");
    ul.textContent = "";
    for (const v of S.silences) {
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
    dirty.layout = true;
    scheduleFrame();
  }

  /** The inhibition rules in force that this console made, each with a Lift button. */
  function setInhibits(list) {
    S.inhibits = (Array.isArray(list) ? list : []).filter((v) => v && typeof v === "object");
    dirty.inhibits = dirty.layout = true;
    scheduleFrame();
  }
  function renderInhibits() {
    const ul = $("inhibits");
    ul.textContent = "";
    const m = (x) => Object.entries(x || {}).map(([k, v]) => `${k} ${(v || []).join(", ")}`).join("; ") || "any";
    for (const r of S.inhibits) {
      const li = el("li", "inhibit", `${r.unit}: while ${m(r.source)}, quiet ${m(r.target)}`
        + `${r.equal && r.equal.length ? " sharing " + r.equal.join(", ") : ""} (${r.id})${r.comment ? " — " + r.comment : ""} `);
      li.dataset.id = r.id;
      li.dataset.unit = r.unit;
      const b = el("button", "lift", "Lift");
      b.type = "button";
      b.addEventListener("click", () => post("uninhibit", { unit: r.unit, id: r.id }));
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
    dirty.escalations = dirty.counts = true;
    scheduleFrame();
    renderTaskorg();
    fillUnitSelect();
    updateActorLabel();
  }

  function onResult(r) {
    if (!r || typeof r !== "object") return;
    const ok = r.ok !== false;
    const who = r.unit || r.owner || "";
    if (ok && (r.kind === "ack" || r.kind === "decide") && typeof r.ref === "string" && r.ref) markAcked(r.ref);   // any console's
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
  /** The snapshot: each part drawn on its own (one that fails leaves the others, the alerts
   * and the counts above all, drawn), alerts and notices replayed in time order. */
  function applyState(st) {
    const first = window.__firstPaintMs === null;
    const step = (name, f) => {
      const t0 = performance.now();
      try { f(); } catch (e) { console.error("state", name, e); }
      if (first) window.__paint[name + "_ms"] = Math.round((performance.now() - t0) * 10) / 10;
    };
    S.scenario = st.scenario || "";
    S.unit = st.unit || null;
    S.units = st.units && typeof st.units === "object" ? st.units : {};
    S.actors = Array.isArray(st.actors) ? st.actors : [];
    $("scenario").textContent = S.scenario;
    document.title = `console ${S.unit || ""} — ${S.scenario}`;
    if (S.filter === "all" && S.unit && !applyState.done) S.filter = S.unit;
    applyState.done = true;
    step("silences", () => renderSilences(st.silences));
    step("inhibits", () => setInhibits(st.inhibits));
    step("units", () => { fillUnitSelect(); $("unit-select").value = S.filter; updateActorLabel(); });
    step("taskorg", renderTaskorg);
    step("missions", fillMissions);
    step("overlay", () => { if (st.overlay && !applyState.overlay) { applyState.overlay = true; loadOverlay(st.overlay); } });
    step("positions", () => updatePositions(st.positions || {}, true));
    step("tracks", () => updateTracks(st.tracks || {}, true));
    S.counts = {};
    step("counts", () => mergeCounts(st.counts || {}));
    setClock(st.t);
    step("alerts", () => {
      const items = [];
      for (const a of [...(Array.isArray(st.alerts) ? st.alerts : []), ...(Array.isArray(st.quiet) ? st.quiet : [])])
        if (a && typeof a === "object") items.push([Number(a.t) || 0, 0, a]);
      for (const n of Array.isArray(st.notices) ? st.notices : [])
        if (n && typeof n === "object") items.push([Number(n.t) || 0, 1, n]);
      items.sort((x, y) => x[0] - y[0] || x[1] - y[1]);   // at one time, alerts before their notices
      let run = [], kind = 0;
      const out = () => { if (run.length) (kind ? addNotices : addAlerts)(run); run = []; };
      for (const [, k, x] of items) { if (k !== kind) { out(); kind = k; } run.push(x); }
      out();
      for (const id of Array.isArray(st.acked) ? st.acked : []) markAcked(id);   // answered before this page opened
    });
    dirty.layout = dirty.quiet = dirty.escalations = dirty.counts = true;
    step("draw", frame);   // drawn now, not at the next frame: the first paint
    if (window.__firstPaintMs === null) window.__firstPaintMs = Math.round(performance.now());
  }

  const HANDLERS = {
    alert: (d) => addAlerts(Array.isArray(d) ? d : [d]),
    alerts: (d) => addAlerts(Array.isArray(d) ? d : [d]),
    notice: (d) => addNotices(Array.isArray(d) ? d : [d]),
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
      if (S.silences.length + S.inhibits.length && performance.now() - lastQuietLayout > 1000) {
        dirty.layout = true;   // a silence may have expired, a rule's source gone quiet
        scheduleFrame();
      }
    },
    tracks: (d) => mapLater("tracks", d),       // the server sends every current track
    positions: (d) => mapLater("positions", d),
    missions: (d) => mergeMissions(d),
    counts: (d) => mergeCounts(d),
    result: (d) => onResult(d),
    org: (d) => applyOrg(d),
    silences: (d) => renderSilences(d),
    inhibits: (d) => setInhibits(d),
  };

  // Positions and tracks are complete snapshots, sent every 100 ms at most: the map takes
  // the latest at most every MAP_EVERY_MS, so moving markers never crowd out the alerts.
  const MAP_EVERY_MS = 500;
  let mapPending = {}, mapTimer = null, lastMap = 0;
  function mapLater(kind, d) {
    mapPending[kind] = d;
    if (mapTimer !== null) return;
    mapTimer = setTimeout(() => {
      mapTimer = null;
      lastMap = performance.now();
      const p = mapPending;
      mapPending = {};
      try {
        if (p.positions) updatePositions(p.positions, true);
        if (p.tracks) updateTracks(p.tracks, true);
      } catch (e) { console.error("map", e); }
      const c = window.__eventMs.map || (window.__eventMs.map = [0, 0]);
      c[0]++;
      c[1] += performance.now() - lastMap;
    }, Math.max(0, MAP_EVERY_MS - (performance.now() - lastMap)));
  }

  let ready = false;
  let early = [];   // events that came before the snapshot

  function dispatch(type, raw) {
    let d;
    try { d = JSON.parse(raw); } catch (e) { console.warn("bad event data", type, e); return; }
    if ((type === "alert" || type === "notice") && d && typeof d === "object")
      d.__recv = performance.timeOrigin + performance.now();   // the render log measures from here
    if (!ready) { early.push([type, d]); return; }
    const t0 = performance.now();
    try { HANDLERS[type](d); } catch (e) { console.error("event", type, e); }
    const w = window.__eventMs;   // where the page's time goes, per kind of event: [count, ms]
    const c = w[type] || (w[type] = [0, 0]);
    c[0]++;
    c[1] += performance.now() - t0;
  }

  async function loadState() {
    const mark = (k) => { if (window.__firstPaintMs === null) window.__paint[k] = Math.round(performance.now()); };
    mark("state_asked");
    const r = await fetch("/api/state", { cache: "no-store" });
    if (!r.ok) throw new Error(`GET /api/state: HTTP ${r.status}`);
    const st = await r.json();
    mark("state_parsed");
    return st;
  }

  /** The live stream: the one index.html opened before the scripts loaded (what came
   * meanwhile is replayed), else a new one. */
  function connect() {
    const boot = window.__boot;
    let es = boot && boot.es;
    if (es) {
      boot.take = dispatch;
      for (const [type, raw] of boot.held.splice(0)) dispatch(type, raw);
    } else {
      es = new EventSource("/events");
      for (const type of Object.keys(HANDLERS)) es.addEventListener(type, (ev) => dispatch(type, ev.data));
    }
    let hadError = false;
    const live = () => { const c = $("conn"); c.textContent = "live"; c.className = "conn up"; };
    es.onopen = () => {
      live();
      if (hadError) {   // reconnected: catch up on what was missed (alerts are deduplicated by id)
        hadError = false;
        loadState().then(applyState).catch((e) => setStatus(String(e), false));
      }
    };
    es.onerror = () => {
      hadError = true;
      const c = $("conn"); c.textContent = "reconnecting"; c.className = "conn down";
    };
    if (es.readyState === 1) live();
    return es;
  }

  async function start() {
    for (const p of PRIORITIES) panes[p] = { ul: $("pane-" + p), count: 0, list: [] };
    renderEscalations();
    initMap();
    wireActions();
    window.__console = { S, map, hms, selectAlert };
    // the stream is open before the snapshot is asked for, so nothing emitted between the two
    // is lost (index.html started both while the scripts loaded; alerts are deduplicated)
    connect();
    try {
      const boot = window.__boot;
      const st = await (boot && boot.state ? boot.state : loadState());
      if (boot && boot.state) {
        window.__paint.state_asked = Math.round(boot.asked_ms);
        window.__paint.state_parsed = Math.round(boot.parsed_ms);
      }
      window.__paint.scripts_ready = Math.round(performance.now());
      applyState(st);
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
