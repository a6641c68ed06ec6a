// The onboard page: polls api/state (relative URL: works behind a proxy under any path),
// draws the track on OpenStreetMap tiles when they load and on a metric grid otherwise,
// the current as an arrow from the vehicle with its one-sigma ellipse at the tip, and
// fills the panel. ?widget=1: compact (Cockpit iframe); ?tiles=0: never ask for tiles;
// ?tile_url=.../{z}/{x}/{y}.png: another tile server (a local one, offline).
// The fleet layer polls api/fleet: the fleet service's current field as arrows with their
// one-sigma ellipse, faded where the sigma is large, nothing where the field is unknown;
// each vehicle's track and its own estimate's arrow.
'use strict';

const params = new URLSearchParams(location.search);
const WIDGET = params.get('widget') === '1';
const USE_TILES = params.get('tiles') !== '0';
const POLL_MS = 1000;
const TRACK_COLOUR = '#1f6fd0';
const ARROW_COLOUR = '#e0301e';
const ELLIPSE_FILL = 'rgba(224, 48, 30, 0.18)';
const VEHICLE_COLOUR = '#1b1f24';
const GRID_COLOUR = '#d5dbe3';
const ARROW_PX_PER_MPS = 120;  // screen length of 1 m/s of current
const MIN_SPAN_M = 60;         // the smallest extent shown
const MAX_TRACK_POINTS = 7200;
const TILE_URL = params.get('tile_url') || 'https://tile.openstreetmap.org/{z}/{x}/{y}.png';
const EARTH_RES = 156543.03392;  // Web Mercator metres per pixel at zoom 0 on the equator
const MAX_TILES = 400;           // tiles kept in memory (the oldest dropped)
const FLEET_POLL_MS = 2000;
const FLEET_COLOUR = '#7b1fa2';          // the field's arrows
const FLEET_ELLIPSE_FILL = 'rgba(123, 31, 162, 0.15)';
const FLEET_TRACK_COLOUR = '#2e7d32';    // the fleet's vehicles' tracks
const FLEET_VEHICLE_COLOUR = '#ef6c00';  // each vehicle's own estimate
const FLEET_STD_FULL = 0.05;   // m/s: a cell this certain or better is drawn opaque
const FLEET_ALPHA_MIN = 0.15;  // the faintest cell drawn
const FLEET_ARROW_OF_SPACING = 0.9;  // the fastest cell's arrow spans this much of a cell
const FLEET_LABEL_CHARS = 16;  // a vehicle's label on the map is cut to this many characters
const M_PER_DEG_LAT = 111132.95, M_PER_DEG_LON_EQ = 111319.49;

let track = [];          // [t, north_m, east_m]
let epoch = -1;
let state = null;
const tiles = new Map(); // 'z/x/y' -> {img, ok}
let tilesFailed = !USE_TILES;
let tilesLoaded = 0;
let fleet = {grid: null, vehicles: [], tracks: {}, origin: null};  // origin: the first grid's centre

const $ = (id) => document.getElementById(id);
// What the page shows of the records (vehicle ids, flags, events: whatever a Zenoh
// publisher put there) goes in as text, never as HTML.
function element(tag, cls, text) {
  const el = document.createElement(tag);
  if (cls) el.className = cls;
  el.textContent = text;
  return el;
}
const fmt = (x, d) => (x === null || x === undefined) ? '?' : x.toFixed(d);
// A heading or bearing (degrees) rounded to d decimals, then wrapped: 359.97 is 0.0, not 360.0.
const bearing = (x, d) => (x === null || x === undefined) ? x : (Number(x.toFixed(d)) % 360 + 360) % 360;
const pm = (v, s, d, unit) => `${fmt(v, d)}${s === null || s === undefined ? '' : ' ± ' + fmt(s, d)} ${unit}`;

if (WIDGET) document.body.classList.add('widget');

async function poll() {
  try {
    const since = track.length ? track[track.length - 1][0] : -1e300;
    const q = new URLSearchParams({since: String(since), epoch: String(epoch)});
    if (params.get('vehicle')) q.set('vehicle', params.get('vehicle'));
    const r = await fetch('api/state?' + q, {cache: 'no-store'});
    if (!r.ok) throw new Error('HTTP ' + r.status);
    const s = await r.json();
    if (s.epoch !== undefined && s.epoch !== epoch) { track = []; epoch = s.epoch; }  // none before the first vehicle
    if (s.track) track.push(...s.track.points);
    if (track.length > MAX_TRACK_POINTS) track.splice(0, track.length - MAX_TRACK_POINTS);
    state = s;
    panel(s);
    draw();
  } catch (err) {
    $('status').textContent = 'no data: ' + err.message;
  }
  setTimeout(poll, POLL_MS);
}

async function pollFleet() {
  try {
    const since = fleet.grid ? fleet.grid.utc : -1e300;
    const q = new URLSearchParams({since: String(since), vehicle: (state && state.vehicle) || params.get('vehicle') || ''});
    const r = await fetch('api/fleet?' + q, {cache: 'no-store'});
    if (r.ok) {
      const f = await r.json();
      if (f.grid) fleet.grid = f.grid;
      fleet.tracks = f.tracks;
      fleet.vehicles = f.vehicles;
      if (!fleet.origin && fleet.grid && fleet.grid.cells.length) fleet.origin = centre(fleet.grid.cells);
      if (!fleet.origin && fleet.vehicles.some(placed)) fleet.origin = centre(fleet.vehicles.filter(placed));
      fleetPanel();
      draw();
    }
  } catch (err) { /* an older service without api/fleet: no fleet layer */ }
  setTimeout(pollFleet, FLEET_POLL_MS);
}

function centre(cells) {
  // The mean place, its longitude taken about the first one's (a fleet across the antimeridian).
  const lat = cells.reduce((a, c) => a + c.lat, 0) / cells.length;
  const lon = cells[0].lon + cells.reduce((a, c) => a + wrapLon(c.lon - cells[0].lon), 0) / cells.length;
  return {lat_deg: lat, lon_deg: wrapLon(lon)};
}

// A vehicle's id as its label on the map: at most FLEET_LABEL_CHARS characters, the rest cut.
const shortLabel = (id) => (String(id).length > FLEET_LABEL_CHARS ? String(id).slice(0, FLEET_LABEL_CHARS - 1) + '…' : String(id));

// A longitude or a difference of two (deg) within [-180, 180]: east the shorter way round.
const wrapLon = (d) => (d > 180 ? d - 360 : d < -180 ? d + 360 : d);

function fleetPanel() {
  // Hidden while there is neither a grid nor another vehicle to tell of.
  const g = fleet.grid;
  $('fleet-box').hidden = !g && !fleet.vehicles.length;
  if (!g && !fleet.vehicles.length) return;
  const n = fleet.vehicles.length, lost = fleet.vehicles.filter((b) => !placed(b)).map((b) => b.vehicle);
  const vehicles = `${n} vehicle${n === 1 ? '' : 's'}` + (lost.length ? ` (${lost.join(', ')} without a position)` : '');
  if (!g) { $('fleet').textContent = `${vehicles} more · no fleet field`; return; }
  const known = g.cells.filter(known_cell).length;
  const t = new Date(g.utc * 1000).toISOString().slice(11, 19);
  $('fleet').textContent = `${known} cells known · ${g.cells.length - known} unknown · ` +
    `${vehicles} · ${Math.round(g.spacing_m)} m cells · ${t} UTC`;
}

const known_cell = (c) => c.north !== null && c.east !== null && c.north !== undefined && c.east !== undefined;
// A vehicle whose records carry no position (an AUV before any fix) is counted, not drawn.
const placed = (b) => Number.isFinite(b.lat) && Number.isFinite(b.lon);

function panel(s) {
  if (s.t === null) { $('status').textContent = `waiting for ${s.vehicle || 'a vehicle'} ...`; return; }
  const age = s.age_s === null ? '' : (s.age_s > 3 ? ` · stale ${s.age_s.toFixed(0)} s` : ' · live');
  const name = document.createElement('b');
  name.textContent = s.vehicle;
  $('status').replaceChildren(name, ` · t ${s.t.toFixed(1)} s${age}`);
  $('speed').textContent = s.speed ? pm(s.speed.value, s.speed.std, 2, 'm/s') : '-';
  $('heading').textContent = s.heading ? pm(bearing(s.heading.value, 1), s.heading.std, 1, '°') : '-';
  const c = s.current;
  if (!c) { $('current').textContent = '-'; $('current-sub').textContent = ''; }
  else if (c.known) {
    $('current').textContent = `${fmt(c.speed_mps, 2)} m/s → ${fmt(bearing(c.towards_deg, 0), 0)}°`;
    $('current-sub').textContent = `N ${pm(c.north_mps, c.std_north_mps, 2, '')} · E ${pm(c.east_mps, c.std_east_mps, 2, 'm/s')}`;
  } else {
    $('current').textContent = 'unknown';
    $('current-sub').textContent = `σ N ${fmt(c.std_north_mps, 2)} · E ${fmt(c.std_east_mps, 2)} m/s`;
  }
  const h = s.health;
  const flags = h ? Object.entries(h.flags) : [];
  $('flags').replaceChildren(...(!h ? ['-'] : flags.length === 0 ? [element('span', 'ok', 'no integrity flag')]
    : flags.map(([p, f]) => element('div', 'warn', `${p}: ${f.join(', ')}`))));
  if (h) {
    const nis = Object.entries(h.nis).map(([k, [v, dof]]) => `${k} ${v.toFixed(2)}/${dof}`).join(' · ');
    $('health').textContent = `mode ${h.mode || '-'} · rejected ${h.rejected} · dropped ${h.dropped}` + (nis ? ` · NIS ${nis}` : '');
    $('events').replaceChildren(...h.events.slice(-8).map((e) => element('li', '', e)));
  }
}

// ---------------------------------------------------------------- the map

function view(w, h) {
  // The extent (local metres) holding the track and the current's arrow, and its scale.
  let n0 = Infinity, n1 = -Infinity, e0 = Infinity, e1 = -Infinity;
  for (const [, n, e] of track) { n0 = Math.min(n0, n); n1 = Math.max(n1, n); e0 = Math.min(e0, e); e1 = Math.max(e1, e); }
  const p = state && state.position;
  if (p) { n0 = Math.min(n0, p.north_m); n1 = Math.max(n1, p.north_m); e0 = Math.min(e0, p.east_m); e1 = Math.max(e1, p.east_m); }
  for (const [n, e] of fleetPoints()) { n0 = Math.min(n0, n); n1 = Math.max(n1, n); e0 = Math.min(e0, e); e1 = Math.max(e1, e); }
  if (!isFinite(n0)) { n0 = e0 = -MIN_SPAN_M / 2; n1 = e1 = MIN_SPAN_M / 2; }
  const cn = (n0 + n1) / 2, ce = (e0 + e1) / 2;
  // the widget's panel lies over the map's right-hand side: centre on what is left
  const free = WIDGET ? Math.max(w / 2, w - $('panel').offsetWidth) : w;
  const margin = Math.min(150, 0.2 * Math.min(free, h));  // room for the arrow
  const mpp = Math.max((n1 - n0) / (h - 2 * margin), (e1 - e0) / (free - 2 * margin),
                       MIN_SPAN_M / Math.min(free, h));
  const x0 = free / 2 - ce / mpp, y0 = h / 2 + cn / mpp;
  return {cn, ce, mpp, w, h, x0, y0, px: (n, e) => [x0 + e / mpp, y0 - n / mpp]};
}

function draw() {
  const canvas = $('canvas');
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = '#f4f6f9'; ctx.fillRect(0, 0, w, h);
  const v = view(w, h);
  const origin = mapOrigin();
  const onTiles = origin && !tilesFailed && drawTiles(ctx, v, origin);
  if (!onTiles) drawGrid(ctx, v);
  const from = (state && state.origin) || !fleet.origin ? 'the first fix' : 'the fleet grid\'s centre';
  $('attribution').textContent = onTiles ? '© OpenStreetMap contributors' : `grid: metres from ${from}`;
  drawTrack(ctx, v);
  drawFleet(ctx, v);
  drawVehicleAndCurrent(ctx, v);
}

function niceStep(m) {
  const p = Math.pow(10, Math.floor(Math.log10(m)));
  return [1, 2, 5, 10].map((k) => k * p).find((s) => s >= m);
}

function drawGrid(ctx, v) {
  const step = niceStep(100 * v.mpp);
  ctx.strokeStyle = GRID_COLOUR; ctx.lineWidth = 1; ctx.fillStyle = '#7a8594'; ctx.font = '11px sans-serif';
  const eMin = -v.x0 * v.mpp, eMax = (v.w - v.x0) * v.mpp;
  const nMin = (v.y0 - v.h) * v.mpp, nMax = v.y0 * v.mpp;
  for (let e = Math.ceil(eMin / step) * step; e <= eMax; e += step) {
    const [x] = v.px(0, e); ctx.beginPath(); ctx.moveTo(x, 0); ctx.lineTo(x, v.h); ctx.stroke();
    ctx.fillText(`${e.toFixed(0)} m E`, x + 2, v.h - 16);
  }
  for (let n = Math.ceil(nMin / step) * step; n <= nMax; n += step) {
    const [, y] = v.px(n, 0); ctx.beginPath(); ctx.moveTo(0, y); ctx.lineTo(v.w, y); ctx.stroke();
    ctx.fillText(`${n.toFixed(0)} m N`, 2, y - 2);
  }
}

function mercator(lat, lon, z) {
  const size = 256 * Math.pow(2, z), phi = lat * Math.PI / 180;
  return [(lon + 180) / 360 * size, (1 - Math.log(Math.tan(phi) + 1 / Math.cos(phi)) / Math.PI) / 2 * size];
}

function drawTiles(ctx, v, origin) {
  // OpenStreetMap tiles under the local metres: true when drawn (some loaded, none failed).
  const mLat = 111132.95, mLon = 111319.49 * Math.cos(origin.lat_deg * Math.PI / 180);
  const nC = (v.y0 - v.h / 2) * v.mpp, eC = (v.w / 2 - v.x0) * v.mpp;  // the screen's centre
  const lat = origin.lat_deg + nC / mLat, lon = origin.lon_deg + eC / mLon;
  const res0 = EARTH_RES * Math.cos(lat * Math.PI / 180);
  const z = Math.max(0, Math.min(19, Math.floor(Math.log2(res0 / v.mpp))));
  const k = res0 / Math.pow(2, z) / v.mpp;  // screen pixels per tile pixel (>= 1)
  const [X, Y] = mercator(lat, lon, z);
  const t0x = Math.floor((X - v.w / 2 / k) / 256), t1x = Math.floor((X + v.w / 2 / k) / 256);
  const t0y = Math.floor((Y - v.h / 2 / k) / 256), t1y = Math.floor((Y + v.h / 2 / k) / 256);
  const n = Math.pow(2, z);  // tiles round the world: past the antimeridian they wrap
  for (let tx = t0x; tx <= t1x; tx++) {
    for (let ty = t0y; ty <= t1y; ty++) {
      const t = tile(z, ((tx % n) + n) % n, ty);
      if (t.ok) ctx.drawImage(t.img, v.w / 2 + (tx * 256 - X) * k, v.h / 2 + (ty * 256 - Y) * k, 256 * k + 1, 256 * k + 1);
    }
  }
  return tilesLoaded > 0;
}

function tile(z, x, y) {
  const key = `${z}/${x}/${y}`;
  let t = tiles.get(key);
  if (!t) {
    t = {img: new Image(), ok: false};
    t.img.onload = () => { t.ok = true; tilesLoaded++; draw(); };
    t.img.onerror = () => { if (tilesLoaded === 0) { tilesFailed = true; draw(); } };
    t.img.src = TILE_URL.replace('{z}', z).replace('{x}', x).replace('{y}', y);
    tiles.set(key, t);
    if (tiles.size > MAX_TILES) tiles.delete(tiles.keys().next().value);
  }
  return t;
}

function drawTrack(ctx, v) {
  if (track.length < 2) return;
  ctx.strokeStyle = TRACK_COLOUR; ctx.lineWidth = 3; ctx.lineJoin = 'round';
  ctx.beginPath();
  track.forEach(([, n, e], i) => { const [x, y] = v.px(n, e); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
  ctx.stroke();
}

function drawVehicleAndCurrent(ctx, v) {
  const p = state && state.position;
  if (!p) return;
  const [x, y] = v.px(p.north_m, p.east_m);
  const c = state.current;
  if (c && c.std_north_mps !== null && c.std_east_mps !== null) {
    const cn = c.known ? c.north_mps : 0, ce = c.known ? c.east_mps : 0;
    const tx = x + ce * ARROW_PX_PER_MPS, ty = y - cn * ARROW_PX_PER_MPS;
    ctx.fillStyle = ELLIPSE_FILL; ctx.strokeStyle = ARROW_COLOUR; ctx.lineWidth = 1;
    ctx.beginPath();
    ctx.ellipse(tx, ty, Math.max(1, c.std_east_mps * ARROW_PX_PER_MPS), Math.max(1, c.std_north_mps * ARROW_PX_PER_MPS), 0, 0, 2 * Math.PI);
    ctx.fill(); ctx.stroke();
    if (c.known) arrow(ctx, x, y, tx, ty, ARROW_COLOUR, 4, 12);
    ctx.fillStyle = ARROW_COLOUR; ctx.font = '11px sans-serif';
    ctx.fillText(`current (${ARROW_PX_PER_MPS} px per m/s, 1σ ellipse)`, 8, 16);
  }
  const hd = state.heading ? state.heading.value * Math.PI / 180 : null;
  ctx.fillStyle = VEHICLE_COLOUR;
  ctx.beginPath();
  if (hd === null) ctx.arc(x, y, 5, 0, 2 * Math.PI);
  else {
    const f = [Math.sin(hd), -Math.cos(hd)], r = [Math.cos(hd), Math.sin(hd)];
    ctx.moveTo(x + 14 * f[0], y + 14 * f[1]);
    ctx.lineTo(x - 6 * f[0] + 5 * r[0], y - 6 * f[1] + 5 * r[1]);
    ctx.lineTo(x - 6 * f[0] - 5 * r[0], y - 6 * f[1] - 5 * r[1]);
    ctx.closePath();
  }
  ctx.fill();
}

function arrow(ctx, x0, y0, x1, y1, colour, width, head) {
  const a = Math.atan2(y1 - y0, x1 - x0);
  ctx.strokeStyle = colour; ctx.fillStyle = colour; ctx.lineWidth = width;
  ctx.beginPath(); ctx.moveTo(x0, y0); ctx.lineTo(x1 - head * 0.8 * Math.cos(a), y1 - head * 0.8 * Math.sin(a)); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - head * Math.cos(a - 0.45), y1 - head * Math.sin(a - 0.45));
  ctx.lineTo(x1 - head * Math.cos(a + 0.45), y1 - head * Math.sin(a + 0.45));
  ctx.closePath(); ctx.fill();
}

// ---------------------------------------------------------------- the fleet layer

function mapOrigin() {
  // The vehicle's origin places everything; a fleet page without one uses the first grid's centre.
  return (state && state.origin) || fleet.origin;
}

function local(lat, lon) {
  // (north, east) metres of (lat, lon) about the map's origin (the page's flat-earth scale).
  const o = mapOrigin();
  return [(lat - o.lat_deg) * M_PER_DEG_LAT, wrapLon(lon - o.lon_deg) * M_PER_DEG_LON_EQ * Math.cos(o.lat_deg * Math.PI / 180)];
}

function fleetPoints() {
  // Every place of the fleet layer in local metres (the extent shown holds them all).
  if (!mapOrigin()) return [];
  const pts = fleet.grid ? fleet.grid.cells.map((c) => local(c.lat, c.lon)) : [];
  for (const b of fleet.vehicles.filter(placed)) pts.push(local(b.lat, b.lon));
  for (const tr of Object.values(fleet.tracks)) for (const [, lat, lon] of tr) pts.push(local(lat, lon));
  return pts;
}

function fleetAlpha(c) {
  // Opaque where the larger sigma is FLEET_STD_FULL or less, fading as it grows.
  const s = Math.max(c.std_north ?? Infinity, c.std_east ?? Infinity);
  return Math.max(FLEET_ALPHA_MIN, Math.min(1, FLEET_STD_FULL / s));
}

function drawFleet(ctx, v) {
  const g = fleet.grid;
  if (!mapOrigin() || (!g && !fleet.vehicles.length)) return;
  const cells = g ? g.cells.filter(known_cell) : [];
  const fastest = Math.max(1e-3, ...cells.map((c) => Math.hypot(c.north, c.east)));
  const scale = g ? Math.min(ARROW_PX_PER_MPS, FLEET_ARROW_OF_SPACING * g.spacing_m / v.mpp / fastest)
                  : ARROW_PX_PER_MPS;  // px per m/s
  for (const c of cells) {
    const [x, y] = v.px(...local(c.lat, c.lon));
    ctx.globalAlpha = fleetAlpha(c);
    currentArrow(ctx, x, y, c.north, c.east, c.std_north, c.std_east, scale, FLEET_COLOUR, FLEET_ELLIPSE_FILL, 2, 7);
  }
  ctx.globalAlpha = 1;
  ctx.strokeStyle = FLEET_TRACK_COLOUR; ctx.lineWidth = 2; ctx.setLineDash([6, 4]);
  for (const tr of Object.values(fleet.tracks)) {
    ctx.beginPath();
    tr.forEach(([, lat, lon], i) => { const [x, y] = v.px(...local(lat, lon)); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    ctx.stroke();
  }
  ctx.setLineDash([]);
  for (const b of fleet.vehicles.filter(placed)) {
    const [x, y] = v.px(...local(b.lat, b.lon));
    if (known_cell(b))
      currentArrow(ctx, x, y, b.north, b.east, b.std_north, b.std_east, scale, FLEET_VEHICLE_COLOUR, 'rgba(239, 108, 0, 0.15)', 3, 9);
    ctx.fillStyle = FLEET_VEHICLE_COLOUR; ctx.beginPath(); ctx.arc(x, y, 4, 0, 2 * Math.PI); ctx.fill();
    ctx.font = '11px sans-serif'; ctx.fillText(shortLabel(b.vehicle), x + 6, y + 12);
  }
  if (!g) return;
  ctx.fillStyle = FLEET_COLOUR; ctx.font = '11px sans-serif';
  ctx.fillText(`fleet field (${scale.toFixed(0)} px per m/s, 1σ ellipse, faint: uncertain)`, 8, 30);
}

function currentArrow(ctx, x, y, north, east, stdN, stdE, scale, colour, fill, width, head) {
  // An arrow of the current from (x, y), its one-sigma ellipse at the tip.
  const tx = x + east * scale, ty = y - north * scale;
  if (stdN !== null && stdE !== null && stdN !== undefined && stdE !== undefined) {
    ctx.fillStyle = fill; ctx.beginPath();
    ctx.ellipse(tx, ty, Math.max(1, stdE * scale), Math.max(1, stdN * scale), 0, 0, 2 * Math.PI);
    ctx.fill();
  }
  arrow(ctx, x, y, tx, ty, colour, width, head);
}

// ---------------------------------------------------------------- configuration

async function loadConfig() {
  const r = await fetch('api/config', {cache: 'no-store'}).catch(() => null);
  if (!r || !r.ok) return;  // the shore, or an older service: no configuration here
  const c = await r.json();
  $('config').hidden = false;
  $('config-target').textContent = c.editable ? `edit ${c.target}` : `${c.target} (read-only: service.web.edit_config = false)`;
  $('config-files').textContent = c.files.map((f) => f.path).join(' + ');
  const last = c.files[c.files.length - 1];
  $('config-text').value = last ? last.text : '';
  $('config-text').readOnly = !c.editable;
  $('config-save').disabled = !c.editable;
}

async function sendConfig(path) {
  const r = await fetch(path, {method: 'POST', headers: {'Content-Type': 'application/json'},
                               body: JSON.stringify({text: $('config-text').value})});
  const out = await r.json().catch(() => ({errors: ['HTTP ' + r.status]}));
  $('config-result').className = out.errors.length ? 'warn' : 'ok';
  $('config-result').textContent = out.errors.length ? out.errors.join('\n')
    : (out.saved ? `saved ${out.target}: applies at the next start` : 'valid');
}

$('config-check').onclick = () => sendConfig('api/config/check');
$('config-save').onclick = () => sendConfig('api/config');
window.addEventListener('resize', draw);
if (!WIDGET) loadConfig();
draw();
poll();
pollFleet();
