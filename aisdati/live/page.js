// The live page's script: polls /state.json every second and redraws the vessels' last
// positions, the open and recent events (a popup each) and the feed's summary, without reload.
// Every text shown is set as text (textContent, or an element given to Leaflet), never HTML.
const map = L.map('map', {zoomSnap: 0.25, preferCanvas: true}).setView([0, 0], 2);
map.attributionControl.setPrefix('Leaflet');
L.control.scale().addTo(map);
const vesselLayer = L.layerGroup().addTo(map);
const eventLayer = L.layerGroup().addTo(map);
let framed = false;
const popups = {};

function rows(pairs) {
  const t = document.createElement('table');
  for (const [k, v] of pairs) {
    const r = t.insertRow();
    r.insertCell().textContent = k;
    r.insertCell().textContent = v === null || v === undefined ? '' : v;
  }
  return t;
}
function eventRows(e) {
  return rows([['vessel', `${e.name || ''} ${e.mmsi}`], ['kind', e.label],
    ['state', e.state], ['since', e.start], ['until', e.state === 'open' ? 'now' : e.end],
    ['strength', e.strength], ['evidence', e.evidence]]);
}
function drawEvents(events) {
  eventLayer.clearLayers();
  const list = document.getElementById('events');
  list.replaceChildren();
  for (const e of events) {
    const colour = e.state === 'open' ? '#d62728' : '#777';
    const where = e.lats.map((lat, i) => [lat, e.lons[i]]);
    const shape = where.length > 1
      ? L.polyline(where, {color: colour, weight: 4})
      : L.circleMarker(where[0], {radius: 8, color: colour});
    shape.bindPopup(() => eventRows(e)).addTo(eventLayer);
    popups[e.id] = shape;
    const item = document.createElement('div');
    item.className = `event ${e.state}`;
    item.dataset.id = e.id;
    item.textContent = `${e.state === 'open' ? 'OPEN' : 'closed'} ${e.label}: ` +
      `${e.name || e.mmsi} since ${e.start.slice(0, 19).replace('T', ' ')}`;
    item.onclick = () => { map.panTo([e.lat, e.lon]); shape.openPopup(); };
    list.appendChild(item);
  }
}
function text(words) {
  // Leaflet renders a string tooltip as HTML: a vessel's name (`<IMG SRC=...>` is one) goes in
  // as an element's text, never as markup.
  const span = document.createElement('span');
  span.textContent = words;
  return span;
}
function drawVessels(vessels) {
  vesselLayer.clearLayers();
  for (const [mmsi, lon, lat, name] of vessels) {
    L.circleMarker([lat, lon], {radius: 3, color: '#1f77b4', weight: 1})
      .bindTooltip(text(`${name || ''} ${mmsi}`)).addTo(vesselLayer);
  }
  if (!framed && vessels.length) {
    map.fitBounds(vessels.map(v => [v[2], v[1]]), {padding: [30, 30], maxZoom: 12});
    framed = true;
  }
}
function drawSummary(s) {
  const clock = s.clock ? new Date(s.clock * 1000).toISOString().slice(0, 19) : '';
  const table = rows([['messages/s', s.messages_per_s], ['vessels', s.vessels],
    ['open events', s.open_events], ['rejected sentences', s.rejected],
    ['reports', s.reports], ['forgotten vessels', s.forgotten], ['feed time (UTC)', clock]]);
  table.id = 'summary';
  for (const [k, v] of Object.entries(s)) table.dataset[k] = v;
  document.getElementById('summary').replaceWith(table);
}
async function poll() {
  try {
    const state = await (await fetch('/state.json', {cache: 'no-store'})).json();
    drawSummary(state.summary);
    drawVessels(state.vessels);
    drawEvents(state.events);
    document.body.dataset.polled = Number(document.body.dataset.polled || 0) + 1;
  } catch (err) {
    document.body.dataset.error = String(err);
  }
  setTimeout(poll, 1000);
}
poll();
