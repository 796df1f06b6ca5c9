/* The review page's interactive network map (trainpos db review).
 *
 * Reads the JSON of dbtools/interchange/netmap.py (+ the changes of mapchanges.map_data) from
 * <script id="review-map-data"> and draws it with the vendored Leaflet (L): tracks (coloured
 * by kind; dashed red: tracks of OLD that NEW no longer has), connections, switches, balise
 * groups, km ticks and the changes, each a layer that the layer control switches on and off.
 * Hover shows a tooltip, click a popup with the same text. No network access unless the page
 * was written with --tiles (then that tile layer is added below everything).
 */
(function () {
  "use strict";
  var D = JSON.parse(document.getElementById("review-map-data").textContent);
  var el = document.getElementById("review-map");
  var KIND = {
    main: "#1f4e99", station: "#2a7d2a", siding: "#8e6c00", crossover: "#b03a9e",
    connecting: "#0f8c8c", yard: "#777777"
  };
  var CHG = { added: "#1a7f37", removed: "#c0392b", moved: "#d4760a" };
  var SWITCH = { point: "#d62728", crossing: "#444444", single_slip: "#9467bd", double_slip: "#8c564b" };

  function esc(t) {
    return String(t).replace(/[&<>"']/g, function (c) {
      return { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;" }[c];
    });
  }
  function km(m) {
    if (m === null || m === undefined) { return "\u2014"; }
    var s = m < 0 ? "-" : "", a = Math.round(Math.abs(m) * 10) / 10, k = Math.floor(a / 1000);
    return s + k + "k" + (a - k * 1000).toFixed(1).padStart(5, "0");
  }
  function decode(c) {
    var out = [], la = 0, lo = 0;
    for (var i = 0; i < c.length; i += 2) {
      la += c[i]; lo += c[i + 1];
      out.push([la / D.scale, lo / D.scale]);
    }
    return out;
  }
  function bind(layer, html) {
    layer.bindTooltip(html, { sticky: true, direction: "top" });
    layer.bindPopup(html);
    return layer;
  }

  var map = L.map(el, { zoomSnap: 0.25, maxZoom: 22, preferCanvas: false });
  map.createPane("points").style.zIndex = 450;
  L.control.scale({ metric: true, imperial: false }).addTo(map);
  if (D.tiles) {
    L.tileLayer(D.tiles, { maxZoom: 19, attribution: esc(D.tiles_attribution || "") }).addTo(map);
  }

  function trackText(t) {
    var where = t.line !== null ? "line " + esc(t.line) + " track " + esc(t.track) + ", km " + km(t.km0) +
      " \u2192 " + km(t.km1) : "along no line km";
    return "<b class='tip-track'>" + esc(t.id) + "</b>" + (t.name ? " " + esc(t.name) : "") +
      "<br>kind " + esc(t.kind) + (t.implied ? " (implied by the line grid)" : "") + "<br>" + where +
      "<br>length " + t.len.toFixed(1) + " m, " + t.points + " centreline points";
  }
  var tracks = L.layerGroup();
  D.tracks.forEach(function (t) {
    var colour = KIND[t.kind] || "#333333";
    var pl = L.polyline(decode(t.c), { color: colour, weight: 3, opacity: 0.9, className: "track kind-" + t.kind });
    pl.on("mouseover", function () { pl.setStyle({ weight: 6 }); });
    pl.on("mouseout", function () { pl.setStyle({ weight: 3 }); });
    bind(pl, trackText(t)).addTo(tracks);
  });
  (D.removed_tracks || []).forEach(function (t) {
    var pl = L.polyline(decode(t.c), { color: CHG.removed, weight: 2, dashArray: "6,4", className: "removed-track" });
    bind(pl, "<b>" + esc(t.id) + "</b><br>line track of OLD not in NEW").addTo(tracks);
  });

  var connections = L.layerGroup();
  D.connections.forEach(function (p) {
    var rows = p.links.map(function (c) {
      return esc(c.a) + " " + esc(c.ea) + " \u2194 " + esc(c.b) + " " + esc(c.eb) + " (" + esc(c.nav) +
        (c.switch ? ", switch " + esc(c.switch) : "") + ")";
    });
    var m = L.circleMarker([p.lat, p.lon], {
      radius: 3, color: "#222222", weight: 1, fillColor: "#ffffff", fillOpacity: 1, className: "connection", pane: "points"
    });
    bind(m, "<b>connection</b><br>" + rows.join("<br>")).addTo(connections);
  });

  var switches = L.layerGroup();
  // close up, each switch also carries a label: id, 1:n and the diverging side (L/R)
  var switchLabels = L.layerGroup();
  D.switches.forEach(function (s) {
    var geo = [];
    if (s.n !== null) { geo.push("1:" + s.n); }
    if (s.side) { geo.push("diverging " + esc(s.side)); }
    if (s.radius !== null) { geo.push("R " + s.radius + " m"); }
    if (s.speed !== null) { geo.push(s.speed + " km/h"); }
    var ports = Object.keys(s.ports).filter(function (k) { return s.ports[k]; }).map(function (k) {
      return k.toUpperCase() + " " + esc(s.ports[k]);
    });
    var m = L.circleMarker([s.lat, s.lon], {
      radius: 6, color: "#ffffff", weight: 1.5, fillColor: SWITCH[s.type] || "#d62728", fillOpacity: 1,
      className: "switch sw-" + s.type, pane: "points"
    });
    bind(m, "<b class='tip-switch'>switch " + esc(s.id) + "</b><br>" + esc(s.type) +
      (geo.length ? ", " + geo.join(", ") : "") + "<br>" + ports.join(", ")).addTo(switches);
    var short = esc(s.id) + (s.n !== null ? " 1:" + s.n : "") + (s.side ? " " + esc(s.side.charAt(0).toUpperCase()) : "");
    L.marker([s.lat, s.lon], {
      icon: L.divIcon({ className: "sw-label", html: short, iconSize: null, iconAnchor: [-8, 8] }),
      interactive: false, keyboard: false, pane: "points"
    }).addTo(switchLabels);
  });

  var groups = L.layerGroup();
  D.groups.forEach(function (g) {
    var m = L.circleMarker([g.lat, g.lon], {
      radius: 5, color: "#4a148c", weight: 1.5, fillColor: "#ce93d8", fillOpacity: 1, className: "balise-group", pane: "points"
    });
    bind(m, "<b>balise group " + esc(g.id) + "</b> (NID_C:NID_BG)<br>" + g.balises.length + " balise(s)" +
      (g.n_total !== null ? " of " + g.n_total : "") + ": " + g.balises.map(esc).join(", ") +
      (g.track ? "<br>track " + esc(g.track) : "") +
      (g.link ? "<br>links to " + esc(g.link) + (g.link_m !== null ? " at " + g.link_m + " m" : "") : "")
    ).addTo(groups);
  });

  // panes: track lines in the overlay pane (z 400), km ticks above them (420), the point
  // markers — connections, switches, balise groups, changes — above the ticks (450)
  map.createPane("ticks").style.zIndex = 420;
  var ticks = L.layerGroup();
  var nTicks = 0;
  D.ticks.forEach(function (t) {
    decode(t.c).forEach(function (at, i) {
      nTicks += 1;
      var m = L.circleMarker(at, {
        radius: 2.5, color: "#555555", weight: 1, fillColor: "#ffffff", fillOpacity: 1, className: "km-tick",
        pane: "ticks"
      });
      bind(m, "km " + km(t.km[i]) + "<br>" + esc(t.track)).addTo(ticks);
    });
  });

  var changes = L.layerGroup();
  (D.changes || []).forEach(function (c) {
    var text = esc(c.what) + " " + esc(c.label) + " " + esc(c.kind) +
      (c.shift !== null ? " " + c.shift.toFixed(2) + " m" : "");
    if (c.kind === "moved" && c.old && c.new) {
      bind(L.polyline([c.old, c.new], { color: CHG.moved, weight: 3, className: "chg moved", pane: "points" }), text).addTo(changes);
      L.circleMarker(c.new, { radius: 4, color: CHG.moved, fillOpacity: 1, interactive: false, pane: "points" }).addTo(changes);
      return;
    }
    var at = c.new || c.old;
    if (!at) { return; }
    var m = L.circleMarker(at, {
      radius: 6, color: "#ffffff", weight: 1.5, fillColor: CHG[c.kind], fillOpacity: 1, className: "chg " + c.kind, pane: "points"
    });
    bind(m, text).addTo(changes);
  });

  [tracks, connections, switches, groups, changes].forEach(function (g) { g.addTo(map); });
  // thousands of km ticks only from close up
  var TICK_ZOOM = nTicks > 2000 ? 13 : 0;
  function showTicks() {
    if (map.getZoom() >= TICK_ZOOM) { ticks.addTo(map); } else { ticks.remove(); }
  }
  L.control.layers(null, {
    "tracks": tracks, "connections": connections, "switches": switches, "balise groups": groups,
    "km ticks": ticks, "changes": changes
  }, { collapsed: false }).addTo(map);

  var legend = L.control({ position: "bottomleft" });
  legend.onAdd = function () {
    var div = L.DomUtil.create("div", "map-legend");
    var kinds = {};
    D.tracks.forEach(function (t) { kinds[t.kind] = true; });
    var rows = Object.keys(KIND).filter(function (k) { return kinds[k]; }).map(function (k) {
      return "<i style='background:" + KIND[k] + "'></i>" + k + " track";
    });
    if (D.removed_tracks && D.removed_tracks.length) {
      rows.push("<i style='background:" + CHG.removed + "'></i>track of OLD only (dashed)");
    }
    var types = {};
    D.switches.forEach(function (s) { types[s.type] = true; });
    Object.keys(SWITCH).filter(function (k) { return types[k]; }).forEach(function (k) {
      rows.push("<i class='dot' style='background:" + SWITCH[k] + "'></i>switch (" + k.replace("_", " ") + ")");
    });
    if (D.connections.length) {
      rows.push("<i class='dot' style='background:#ffffff;border:1px solid #222'></i>connection");
    }
    if (D.groups.length) { rows.push("<i class='dot' style='background:#ce93d8'></i>balise group"); }
    if (nTicks) {
      rows.push("<i class='dot' style='background:#fff;border:1px solid #555'></i>km tick (every km" +
        (TICK_ZOOM ? ", from zoom " + TICK_ZOOM : "") + ")");
    }
    if (D.changes && D.changes.length) {
      rows.push("<i class='dot' style='background:" + CHG.added + "'></i>added, <i class='dot' style='background:" +
        CHG.removed + "'></i>removed, <i style='background:" + CHG.moved + "'></i>moved (true scale)");
    }
    div.innerHTML = "<b>Legend</b><br>" + rows.join("<br>");
    return div;
  };
  legend.addTo(map);

  if (D.bounds) {
    map.fitBounds(D.bounds, { padding: [20, 20] });
  } else {
    map.setView([0, 0], 2);
  }
  var LABEL_ZOOM = 16;
  function showLabels() {
    if (map.getZoom() >= LABEL_ZOOM && map.hasLayer(switches)) { switchLabels.addTo(map); } else { switchLabels.remove(); }
  }
  map.on("zoomend", showTicks);
  map.on("zoomend overlayadd overlayremove", showLabels);
  showTicks();
  showLabels();
  el.setAttribute("data-ready", "1");
})();
