// The detection page's script: builds the Leaflet layers from the page's JSON data
// (aisdati/detection/webmap.py writes both into one self-contained HTML file).
const D = JSON.parse(document.getElementById('aisdati-data').textContent);
const map = L.map('map', {zoomSnap: 0.25, preferCanvas: false});
document.getElementById('map').style.background = D.style.water;
map.attributionControl.setPrefix('Leaflet');
L.control.scale().addTo(map);

function table(p) {
  const t = document.createElement('table');
  for (const [k, v] of Object.entries(p)) {
    if (k === 'colour' || k === 'max_dev_lon' || k === 'max_dev_lat') continue;
    const r = t.insertRow();
    r.insertCell().textContent = k;
    r.insertCell().textContent = v;
  }
  return t;
}
function label(p) {
  if (p.label) return p.label;
  const s = (p.score !== undefined) ? ` — score ${p.score}` : '';
  return `track ${p.track_id}${s}`;
}
function lines(fc, style, popup) {
  return L.geoJSON(fc, {
    style: f => Object.assign({}, style, f.properties.colour ? {color: f.properties.colour} : {}),
    onEachFeature: (f, layer) => {
      layer.bindTooltip(label(f.properties), {sticky: true});
      if (popup) layer.bindPopup(() => table(f.properties));
    },
  });
}
const overlays = {};
if (D.land) {
  overlays[D.names.coast] = L.geoJSON(D.land, {interactive: false, attribution: D.coast_attribution,
    style: {color: D.style.coast, weight: 0.7, fillColor: D.style.land, fillOpacity: 1}});
}
const L_ = D.layers;
if (D.optional.medoids) overlays[D.names.medoids] = lines(D.optional.medoids,
  {color: '#7b3294', weight: 3, dashArray: '8 6'}, false);
overlays[D.names.tracks] = lines(L_.tracks, {weight: 1.6, opacity: 0.85}, true);
if (D.optional.best) overlays[D.names.best] = lines(D.optional.best,
  {color: '#6baed6', weight: 1.5, opacity: 0.7}, false);
overlays[D.names.rollouts] = lines(L_.rollouts, {color: '#1f77b4', weight: 2}, false);
const flagged = lines(L_.flagged, {weight: 3}, true);
L.geoJSON(L_.deviations, {
  pointToLayer: (f, ll) => L.circleMarker(ll, {radius: 6, color: 'black', weight: 2, fill: true, fillOpacity: 0.3}),
  onEachFeature: (f, layer) => {
    layer.bindTooltip(`track ${f.properties.track_id}: largest deviation ${f.properties.max_dev_m} m`);
    layer.bindPopup(() => table(f.properties));
  },
}).eachLayer(l => flagged.addLayer(l));
overlays[D.names.flagged] = flagged;
if (D.optional.stretches) overlays[D.names.stretches] = lines(D.optional.stretches,
  {color: '#ff7f0e', weight: 6, opacity: 0.8}, false);
// alerts orange and solid, activity (loitering: listed, flagging nothing) blue and dashed; a gap
// is no path sailed: a thin dotted link from the last report before it to the first after,
// labelled with its duration
const isGap = f => f.properties.kind === 'gap';
const eventStyle = f => isGap(f) ? {color: '#3182bd', weight: 2, opacity: 0.9, dashArray: '2 6'}
  : f.properties.class === 'alert' ? {color: '#e6550d', weight: 7, opacity: 0.85}
  : {color: '#3182bd', weight: 4, opacity: 0.7, dashArray: '6'};
function duration(s) {
  if (s < 120) return `${Math.round(s)} s`;
  return s < 7200 ? `${Math.round(s / 60)} min` : `${(s / 3600).toFixed(1)} h`;
}
// the vessels an event names: its own, and a fleet event's others (an encounter's two, drawn
// as one line each)
const named = p => [p.name || p.mmsi,
  ...(p.others ? JSON.parse(p.others).map(o => o.name || o.mmsi) : [])].join(' and ');
if (D.optional.events) overlays[D.names.events] = L.geoJSON(D.optional.events, {
  style: eventStyle,
  pointToLayer: (f, ll) => L.circleMarker(ll, {radius: 7, weight: 3, ...eventStyle(f)}),
  onEachFeature: (f, layer) => {
    const p = f.properties;
    if (isGap(f)) {
      layer.bindTooltip(`gap ${duration(p.duration_s)}`, {permanent: true, direction: 'center', className: 'aisdati-gap'});
    } else {
      layer.bindTooltip(`${p.class}, ${p.label}: ${named(p)} from ${p.start}`, {sticky: true});
    }
    layer.bindPopup(() => table(p));
  },
});
const boxes = L.layerGroup(D.regions.map(b => L.rectangle(b, {color: 'black', weight: 1, dashArray: '5', fill: false, interactive: false})));
overlays[D.names.regions] = boxes;
for (const [name, layer] of Object.entries(overlays)) {
  if (name !== D.names.best) layer.addTo(map);
}
const offline = L.layerGroup().addTo(map);
const tiles = L.tileLayer(D.tile_url, {maxZoom: 18, attribution: '&copy; OpenStreetMap contributors'});
const bases = {};
bases[D.names.offline] = offline;
bases[D.names.tiles] = tiles;
L.control.layers(bases, overlays, {collapsed: false}).addTo(map);
const bar = L.control({position: 'bottomright'});
bar.onAdd = () => {
  const div = L.DomUtil.create('div', 'aisdati-legend');
  const [lo, hi] = D.legend.range;
  div.innerHTML = '<div>track score</div><div class="aisdati-bar"></div>' +
    `<div><span>${lo.toPrecision(3)}</span><span style="float:right">${hi.toPrecision(3)}</span></div>` +
    '<div><span class="aisdati-swatch" style="background:#d62728"></span> flagged track</div>' +
    '<div><span class="aisdati-line" style="border-top:2px solid #1f77b4"></span> what it was compared with</div>' +
    '<div><span class="aisdati-dot"></span> largest deviation</div>' +
    '<div><span class="aisdati-line" style="border-top:6px solid #ff7f0e"></span> stretch of largest deviation</div>' +
    '<div><span class="aisdati-line" style="border-top:7px solid #e6550d"></span> alert</div>' +
    '<div><span class="aisdati-line" style="border-top:4px dashed #3182bd"></span> activity (loitering)</div>' +
    '<div><span class="aisdati-line" style="border-top:2px dotted #3182bd"></span> gap, labelled with its duration</div>' +
    '<div><span class="aisdati-line" style="border-top:1px dashed black"></span> model region</div>';
  div.querySelector('.aisdati-bar').style.background =
    `linear-gradient(to right, ${D.legend.stops.join(', ')})`;
  return div;
};
bar.addTo(map);
if (D.bounds) map.fitBounds(D.bounds, {padding: [10, 10]}); else map.setView([0, 0], 2);
