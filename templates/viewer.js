// A small offline 3D viewer for the report: orbit, zoom and pan over beams, panels and supports.
// Canvas 2D with depth-sorted polygons, so it draws everywhere (also where WebGL is off).
(function () {
  "use strict";
  var source = document.getElementById("viewer-data");
  var canvas = document.getElementById("viewer");
  if (!source || !canvas) { return; }
  var data = JSON.parse(source.textContent);
  if (!data) { return; }
  var context = canvas.getContext("2d");
  var nodes = data.nodes, beams = data.beams, panels = data.panels || [];
  var values = data.beamValues || null;
  var radius = 0;
  nodes.forEach(function (p) { radius = Math.max(radius, Math.hypot(p[0], p[1], p[2])); });
  radius = radius || 1;
  var initial = { yaw: -0.6, pitch: 0.55, zoom: 1, panX: 0, panY: 0 };
  var view = Object.assign({}, initial);
  var maxValue = 0;
  if (values) { values.forEach(function (v) { maxValue = Math.max(maxValue, Math.abs(v)); }); }

  function rotate(p) {
    // z up in the model; yaw about z, then pitch about the screen x axis.
    var cy = Math.cos(view.yaw), sy = Math.sin(view.yaw);
    var x = cy * p[0] - sy * p[1], y = sy * p[0] + cy * p[1], z = p[2];
    var cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    return [x, cp * z - sp * y, sp * z + cp * y];  // screen x, screen up, depth (towards the viewer)
  }

  function beamColour(i) {
    if (!values || !document.getElementById("show-values").checked || maxValue === 0) { return "#1d2330"; }
    var t = Math.min(1, Math.abs(values[i]) / maxValue);
    var shade = Math.round(200 * (1 - t));
    return values[i] < 0 ? "rgb(200," + shade + "," + shade + ")" : "rgb(" + shade + "," + shade + ",200)";
  }

  function draw() {
    var ratio = window.devicePixelRatio || 1;
    var width = canvas.clientWidth, height = canvas.clientHeight;
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    context.setTransform(ratio, 0, 0, ratio, 0, 0);
    context.fillStyle = "#fbfcfd";
    context.fillRect(0, 0, width, height);
    var scale = 0.45 * Math.min(width, height) / radius * view.zoom;
    var projected = nodes.map(rotate);
    var screen = projected.map(function (q) {
      return [width / 2 + view.panX + scale * q[0], height / 2 + view.panY - scale * q[1], q[2]];
    });
    var items = [];
    if (document.getElementById("show-panels").checked) {
      panels.forEach(function (loop) {
        var depth = 0, nx = 0, ny = 0, nz = 0;
        for (var k = 0; k < loop.length; k++) {
          var a = projected[loop[k]], b = projected[loop[(k + 1) % loop.length]];
          depth += a[2];
          nx += (a[1] - b[1]) * (a[2] + b[2]); ny += (a[2] - b[2]) * (a[0] + b[0]); nz += (a[0] - b[0]) * (a[1] + b[1]);
        }
        var light = Math.abs(nz) / (Math.hypot(nx, ny, nz) || 1);
        items.push({ kind: 0, depth: depth / loop.length, loop: loop, light: light });
      });
    }
    beams.forEach(function (beam, i) {
      items.push({ kind: 1, depth: 0.5 * (projected[beam[0]][2] + projected[beam[1]][2]) + 1e-6 * radius, beam: beam, index: i });
    });
    items.sort(function (a, b) { return a.depth - b.depth; });
    context.lineCap = "round";
    items.forEach(function (item) {
      if (item.kind === 0) {
        context.beginPath();
        item.loop.forEach(function (n, k) {
          var s = screen[n];
          if (k === 0) { context.moveTo(s[0], s[1]); } else { context.lineTo(s[0], s[1]); }
        });
        context.closePath();
        var tone = Math.round(150 + 90 * item.light);
        context.fillStyle = "rgba(" + (tone - 40) + "," + (tone - 10) + "," + tone + ",0.55)";
        context.fill();
      } else {
        var a = screen[item.beam[0]], b = screen[item.beam[1]];
        context.strokeStyle = beamColour(item.index);
        context.lineWidth = 1.6;
        context.beginPath();
        context.moveTo(a[0], a[1]);
        context.lineTo(b[0], b[1]);
        context.stroke();
      }
    });
    context.fillStyle = "#000";
    (data.supports || []).forEach(function (n) {
      var s = screen[n];
      context.beginPath();
      context.moveTo(s[0], s[1]);
      context.lineTo(s[0] - 5, s[1] + 8);
      context.lineTo(s[0] + 5, s[1] + 8);
      context.closePath();
      context.fill();
    });
    window.gridshellViewer = { drawn: true, items: items.length, view: Object.assign({}, view) };
  }

  var drag = null;
  canvas.addEventListener("pointerdown", function (event) {
    drag = { x: event.clientX, y: event.clientY, pan: event.shiftKey };
    canvas.setPointerCapture(event.pointerId);
  });
  canvas.addEventListener("pointermove", function (event) {
    if (!drag) { return; }
    var dx = event.clientX - drag.x, dy = event.clientY - drag.y;
    drag.x = event.clientX; drag.y = event.clientY;
    if (drag.pan) { view.panX += dx; view.panY += dy; }
    else {
      view.yaw += dx * 0.01;
      view.pitch = Math.max(-1.55, Math.min(1.55, view.pitch + dy * 0.01));
    }
    draw();
  });
  canvas.addEventListener("pointerup", function () { drag = null; });
  canvas.addEventListener("wheel", function (event) {
    event.preventDefault();
    view.zoom = Math.max(0.1, Math.min(40, view.zoom * Math.exp(-event.deltaY * 0.001)));
    draw();
  }, { passive: false });
  canvas.addEventListener("dblclick", function () { view = Object.assign({}, initial); draw(); });
  document.getElementById("show-panels").addEventListener("change", draw);
  document.getElementById("show-values").addEventListener("change", draw);
  window.addEventListener("resize", draw);
  draw();
})();
