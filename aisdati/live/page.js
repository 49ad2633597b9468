// The live page's script: polls /state.json every second and redraws, without a reload, the
// vessels (an arrow along each one's heading or course), the events on the map and in the list
// (open first, then recent; filtered by class and kind), the feed's health, and the vessel
// chosen (its last reports and events). The coastline of the box in view comes from
// /land.json, asked again as the view moves (finer as it zooms in). The filters and the chosen
// vessel live in the address's #fragment (class=alert&kind=drift&vessel=MMSI).
// Every text shown is set as text (textContent, or an element given to Leaflet), never HTML.
const map = L.map('map', {zoomSnap: 0.25, preferCanvas: true}).setView([0, 0], 2);
map.attributionControl.setPrefix('Leaflet');
L.control.scale().addTo(map);
map.createPane('land').style.zIndex = 350;
const coastLayer = L.geoJSON(null, {pane: 'land', interactive: false}).addTo(map);
const eventLayer = L.layerGroup().addTo(map);
const trackLayer = L.layerGroup().addTo(map);
const vesselLayer = L.layerGroup().addTo(map);
const labelLayer = L.layerGroup().addTo(map);
const shapes = {};
let latest = {summary: {}, vessels: [], events: [], reports: {}};
let framed = false;
let shown = null;
const view = new URLSearchParams(location.hash.slice(1));
const TYPE_COLOURS = {Cargo: '#2f9e44', Tanker: '#b5651d', Passenger: '#1c7ed6',
  Fishing: '#7048e8', Tug: '#0c8599', Pilot: '#0c8599', Towing: '#0c8599',
  'High speed craft': '#d6336c', 'Pleasure craft': '#ae3ec9', Sailing: '#ae3ec9'};

function text(words) {
  // Leaflet renders a string tooltip as HTML: a vessel's name (`<IMG SRC=...>` is one) goes in
  // as an element's text, never as markup.
  const span = document.createElement('span');
  span.textContent = words;
  return span;
}
function rows(table, pairs) {
  table.replaceChildren();
  for (const cells of pairs) {
    const r = table.insertRow();
    for (const c of cells) r.insertCell().textContent = c === null || c === undefined ? '' : c;
  }
  return table;
}
function utc(seconds) { return new Date(seconds * 1000).toISOString().slice(0, 19).replace('T', ' '); }
function duration(s) {
  if (s === null || s === undefined) return '';
  if (s < 90) return `${Math.round(s)} s`;
  if (s < 5400) return `${Math.round(s / 60)} min`;
  if (s < 172800) return `${(s / 3600).toFixed(1)} h`;
  return `${Math.round(s / 86400).toLocaleString('en')} d`;
}
function place(lat, lon) {
  return `${Math.abs(lat).toFixed(3)}${lat < 0 ? 'S' : 'N'} ${Math.abs(lon).toFixed(3)}${lon < 0 ? 'W' : 'E'}`;
}
function saveView() {
  for (const [k, v] of view) if (!v) view.delete(k);
  history.replaceState(null, '', `#${view}`);
}

// The coastline: the land of the box in view (and as much around), asked when the view leaves
// the box it has or zooms in past it.
let land = null;
async function coast() {
  if (!framed) return;  // nothing to show yet: no land asked for the whole world
  const b = map.getBounds();
  const span = Math.max(b.getEast() - b.getWest(), b.getNorth() - b.getSouth());
  if (land && land.box[0] <= b.getWest() && land.box[1] <= b.getSouth() &&
      land.box[2] >= b.getEast() && land.box[3] >= b.getNorth() &&
      span * 8 > land.box[2] - land.box[0]) return;
  const bbox = [b.getWest(), b.getSouth(), b.getEast(), b.getNorth()].map(v => v.toFixed(4));
  try {
    land = await (await fetch(`/land.json?bbox=${bbox}`)).json();
  } catch (err) {
    document.body.dataset.error = `coastline: ${err}`;
    return;
  }
  coastLayer.clearLayers().addData(land.land);
  coastLayer.setStyle({color: land.style.coast, weight: 0.8, fillColor: land.style.land, fillOpacity: 1});
  document.getElementById('map').style.background = land.style.water;
  map.attributionControl.addAttribution(land.attribution);
  document.body.dataset.coast = coastLayer.getLayers().length;
}
map.on('moveend', coast);

function eventsOf(mmsi) { return latest.events.filter(e => e.mmsi === mmsi); }
function alerted(mmsi) { return latest.events.some(e => e.mmsi === mmsi && e.state === 'open' && e.class === 'alert'); }
function arrow(lat, lon, degrees, size) {
  // A triangle pointing along `degrees` (clockwise from north), `size` pixels long at this zoom.
  const p = map.latLngToLayerPoint([lat, lon]);
  const r = degrees * Math.PI / 180;
  const at = (dx, dy) => map.layerPointToLatLng(L.point(
    p.x + dx * Math.cos(r) - dy * Math.sin(r), p.y + dx * Math.sin(r) + dy * Math.cos(r)));
  return [at(0, -size), at(size * 0.55, size * 0.6), at(0, size * 0.25), at(-size * 0.55, size * 0.6)];
}
function label(lat, lon, name, ring) {
  // The chosen vessel's and the alerted vessels' names on the map (not tooltips: those are the
  // hover's), as an element's text.
  const tag = document.createElement('span');
  tag.textContent = name;
  L.marker([lat, lon], {interactive: false, keyboard: false,
    icon: L.divIcon({className: 'vessel-label', html: tag, iconSize: null, iconAnchor: [-14, 8]})})
    .addTo(labelLayer);
  if (ring) L.circleMarker([lat, lon], {radius: 17, color: '#1c7ed6', weight: 2, fill: false, interactive: false}).addTo(labelLayer);
}
function drawVessels() {
  vesselLayer.clearLayers();
  labelLayer.clearLayers();
  for (const [mmsi, lon, lat, name, , type, sog, cog, heading] of latest.vessels) {
    const fill = TYPE_COLOURS[type] || '#66788a';
    const style = {color: alerted(mmsi) ? '#d62728' : '#27303a', weight: alerted(mmsi) ? 2 : 1,
      fillColor: fill, fillOpacity: 0.95};
    const course = heading ?? (sog > 0.5 ? cog : null);
    const mark = course === null || course === undefined
      ? L.circleMarker([lat, lon], {radius: 5, ...style})
      : L.polygon(arrow(lat, lon, course, 14), style);
    mark.bindTooltip(text(`${name || ''} ${mmsi}${type ? ` · ${type}` : ''}`))
      .on('click', () => choose(mmsi)).addTo(vesselLayer);
    if (mmsi === chosen() || alerted(mmsi)) label(lat, lon, name || String(mmsi), mmsi === chosen());
  }
  if (!framed && latest.vessels.length) {
    const places = latest.vessels.map(v => [v[2], v[1]]);
    framed = true;  // before the move, whose end asks for the coastline
    map.fitBounds(places, {padding: [40, 40], maxZoom: 11});
  }
}
map.on('zoomend', drawVessels);

const legend = L.control({position: 'bottomleft'});
legend.onAdd = () => {
  const div = L.DomUtil.create('div', 'legend');
  const types = {};  // a colour's ship types, named together
  for (const [type, colour] of Object.entries(TYPE_COLOURS)) (types[colour] ||= []).push(type);
  const marks = [...Object.entries(types).map(([colour, names]) => [names.join(', '), colour, 'type']),
    ['other, unknown', '#66788a', 'type'], ['open alert', '#d62728', 'line'],
    ['open activity', '#e07b00', 'line'], ['closed event', '#7b8794', 'line']];
  for (const [name, colour, mark] of marks) {
    const row = L.DomUtil.create('div', '', div);
    L.DomUtil.create('i', mark, row).style.background = colour;
    row.append(name);
  }
  return div;
};
legend.addTo(map);

function eventRows(e) {
  const table = document.createElement('table');
  return rows(table, [['vessel', `${e.name || ''} ${e.mmsi}`], ['kind', `${e.label} (${e['class']})`],
    ['state', e.state], ['since', utc(Date.parse(e.start) / 1000)],
    ['until', e.state === 'open' ? 'now' : utc(Date.parse(e.end) / 1000)],
    ['for', duration(e.duration_s)], ['where', place(e.lat, e.lon)],
    ['strength', e.strength], ['evidence', e.evidence]]);
}
function visible(e) {
  return (!view.get('class') || e['class'] === view.get('class')) &&
    (!view.get('kind') || e.kind === view.get('kind'));
}
function points(e) {  // an event's positions; null parts a fleet event's vessels
  return e.lats.map((lat, i) => [lat, e.lons[i]]).filter(p => p[0] !== null);
}
function parts(e) {
  const out = [[]];
  e.lats.forEach((lat, i) => lat === null ? out.push([]) : out[out.length - 1].push([lat, e.lons[i]]));
  return out.filter(p => p.length);
}
function zoomTo(e) {
  const where = points(e);
  map.fitBounds(L.latLngBounds(where).pad(0.5), {maxZoom: 14});
  shapes[e.id].openPopup(L.latLng(e.lat, e.lon));
  shown = e.id;
  for (const r of document.querySelectorAll('tr.event')) r.classList.toggle('chosen', r.dataset.id == e.id);
}
function eventRow(e) {
  const r = document.createElement('tr');
  r.className = `event ${e.state} ${e['class']}`;
  Object.assign(r.dataset, {id: e.id, kind: e.kind, 'class': e['class'], mmsi: e.mmsi});
  r.classList.toggle('chosen', e.id === shown);
  const badge = document.createElement('span');
  badge.className = 'badge';
  badge.textContent = e.state === 'open' ? 'OPEN' : 'closed';
  const who = [e, ...(e.others || [])].map(v => v.name || String(v.mmsi)).join(' + ');
  const cells = [null, e.label, who, utc(Date.parse(e.start) / 1000).slice(5),
    e.state === 'open' ? `${duration(e.duration_s)}+` : duration(e.duration_s), place(e.lat, e.lon)];
  ['state', 'kind', 'who', 'when', 'for', 'where'].forEach((name, i) => {
    const c = r.insertCell();
    c.className = name;
    if (cells[i] === null) c.appendChild(badge); else c.textContent = cells[i];
  });
  r.title = e.evidence;
  r.onclick = () => zoomTo(e);
  return r;
}
function drawEvents() {
  eventLayer.clearLayers();
  const body = document.querySelector('#events tbody');
  body.replaceChildren();
  for (const e of latest.events) {
    const colour = e.state !== 'open' ? '#7b8794' : e['class'] === 'alert' ? '#d62728' : '#e07b00';
    const where = points(e), style = {color: colour, weight: 5, opacity: 0.8, dashArray: e.state === 'open' ? null : '6 4'};
    const shape = e.area ? L.polygon(where, {...style, weight: 2, fillOpacity: 0.2})
      : where.length > 1 ? L.polyline(parts(e), style)
      : L.circleMarker(where[0], {radius: 9, color: colour, weight: 3, fill: false});
    shape.bindPopup(() => eventRows(e));
    shapes[e.id] = shape;
    const row = eventRow(e);
    row.hidden = !visible(e);
    if (!row.hidden) shape.addTo(eventLayer);
    body.appendChild(row);
  }
}
function drawFilters() {
  const kinds = document.getElementById('kind-filter');
  if (kinds.options.length === 1 && latest.kinds) {
    for (const [name, k] of Object.entries(latest.kinds)) {
      const o = document.createElement('option');
      o.value = name;
      o.textContent = `${k.label} (${k['class']})`;
      kinds.appendChild(o);
    }
  }
  kinds.value = view.get('kind') || '';
  document.getElementById('class-filter').value = view.get('class') || '';
}
for (const [id, key] of [['kind-filter', 'kind'], ['class-filter', 'class']]) {
  document.getElementById(id).onchange = ev => { view.set(key, ev.target.value); saveView(); drawEvents(); };
}

function drawSummary() {
  const s = latest.summary;
  const tiles = document.getElementById('summary');
  const alerts = latest.events.filter(e => e.state === 'open' && e['class'] === 'alert').length;
  tiles.replaceChildren();
  for (const [name, value] of [['messages/s', s.messages_per_s], ['vessels', s.vessels],
    ['open alerts', alerts], ['lag', duration(s.lag_s)], ['reports', s.reports],
    ['open events', s.open_events], ['rejected', s.rejected], ['forgotten', s.forgotten]]) {
    const tile = document.createElement('div');
    tile.className = 'tile';
    const v = document.createElement('div');
    v.className = 'value';
    v.textContent = typeof value === 'number' ? value.toLocaleString('en') : (value ?? '');
    const n = document.createElement('div');
    n.className = 'name';
    n.textContent = name;
    tile.append(v, n);
    tiles.appendChild(tile);
  }
  for (const [k, v] of Object.entries(s)) tiles.dataset[k] = v;
  document.getElementById('clock').textContent = s.clock
    ? `feed time ${utc(s.clock)} UTC` : 'waiting for the feed';
  const reasons = Object.entries(latest.rejected || {});
  rows(document.getElementById('rejected'),
    reasons.length ? reasons.map(([k, n]) => [k, n.toLocaleString('en')]) : [['none', '']]);
}

function chosen() { return view.get('vessel') ? Number(view.get('vessel')) : null; }
function choose(mmsi) { view.set('vessel', mmsi); saveView(); drawVessel(); poll(); }
function drawVessel() {
  const mmsi = chosen();
  const box = document.getElementById('vessel');
  const v = latest.vessels.find(v => v[0] === mmsi);
  box.hidden = !v;
  trackLayer.clearLayers();
  if (!v) return;
  const [, , , name, heard, type, sog, cog, heading] = v;
  document.getElementById('vessel-name').textContent = `${name || 'unnamed'} · MMSI ${mmsi}`;
  document.getElementById('vessel-about').textContent =
    `${type || 'type unknown'} · last heard ${utc(heard)} UTC · ${sog ?? '-'} kn, course ${cog ?? '-'}, heading ${heading ?? '-'}`;
  const reports = latest.reports[mmsi] || [];
  const table = rows(document.getElementById('reports'),
    reports.map(([t, lon, lat, s, c, h]) => [utc(t).slice(11), place(lat, lon), s, c, h]));
  const head = table.createTHead().insertRow();
  for (const h of ['time', 'where', 'kn', 'course', 'heading']) {
    const th = document.createElement('th');
    th.textContent = h;
    head.appendChild(th);
  }
  if (reports.length > 1) L.polyline(reports.map(r => [r[2], r[1]]), {color: '#1f2933', weight: 2, dashArray: '3 3'}).addTo(trackLayer);
  const mine = document.getElementById('vessel-events');
  mine.replaceChildren();
  const events = eventsOf(mmsi);
  for (const e of events) mine.appendChild(eventRow(e));
  if (!events.length) rows(mine, [['no events']]);
}

async function poll() {
  try {
    const asked = chosen() ? `?vessel=${chosen()}` : '';
    latest = await (await fetch(`/state.json${asked}`, {cache: 'no-store'})).json();
    drawSummary();
    drawFilters();
    drawVessels();
    drawEvents();
    drawVessel();
    document.body.dataset.polled = Number(document.body.dataset.polled || 0) + 1;
  } catch (err) {
    document.body.dataset.error = String(err);
  }
}
poll();
setInterval(poll, 1000);
