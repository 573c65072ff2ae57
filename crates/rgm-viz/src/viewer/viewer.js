// rgm's viewer of a registration: WebGL 1, no library. The data (rgm-viz's html.rs) is one JSON
// object whose point arrays are base64 of little-endian f32 (x, y, z) rows in the page's frame
// (centred, within [-1, 1]); `after` moves the source into the target's frame.
// A page of many scans merged (rgm-viz's model.rs, `data.model`) shows the merged model with
// each point coloured by its scan, and toggles to the scans as given (`#before` opens there).
// With `#selftest` in the URL it draws both states, compares them and writes a verdict into
// #selftest, for scripts/test-browser.sh; `#before` opens it on the clouds before the transform.
"use strict";
(function () {
  var data = JSON.parse(document.getElementById("rgm-data").textContent);
  var selftest = location.hash.indexOf("selftest") >= 0;

  // Colours (r, g, b in 0..1), as in `rgm render`'s PNG: source orange, target blue.
  var COLOURS = {
    source: [0.94, 0.51, 0.08],
    inlier: [0.10, 0.65, 0.25],
    outlier: [0.85, 0.10, 0.45],
    target: [0.12, 0.35, 0.86],
    line: [0.30, 0.30, 0.30],
  };
  var BACKGROUND = [1, 1, 1];
  // Kinds of vertex: which colour it takes and whether `after` moves it.
  var KIND = { outlier: 0, inlier: 1, target: 2, lineSource: 3, lineTarget: 4, scan: 5 };

  function bytesOf(b64) {
    var text = atob(b64);
    var bytes = new Uint8Array(text.length);
    for (var i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
    return bytes;
  }
  if (new Uint8Array(new Float32Array([1]).buffer)[3] !== 0x3f) {
    throw new Error("rgm's viewer reads little-endian floats; this machine is big-endian");
  }
  function floatsOf(b64) {
    var bytes = bytesOf(b64);
    return new Float32Array(bytes.buffer, 0, bytes.length / 4); // (N, 3)
  }

  function scansOf(b64) {
    var bytes = bytesOf(b64);
    return new Uint16Array(bytes.buffer, 0, bytes.length / 2); // (N,)
  }
  var model = data.model || null;
  // A model page: the scans as given in the source's place, the merged model in the target's
  // (the view centres on it); nothing moves by `after`.
  var sourceXyz = floatsOf(model ? model.given.xyz : data.source.xyz); // (n, 3)
  var targetXyz = floatsOf(model ? model.xyz : data.target.xyz); // (m, 3)
  var inlier = model ? new Uint8Array(0) : bytesOf(data.inlier); // (n,)
  var lineSource = model ? new Float32Array(0) : floatsOf(data.correspondences.source); // (k, 3)
  var lineTarget = model ? new Float32Array(0) : floatsOf(data.correspondences.target); // (k, 3)
  var n = sourceXyz.length / 3, m = targetXyz.length / 3, k = lineSource.length / 3;
  // A scan's colour: hues a golden angle apart, so that neighbours in the list differ.
  function scanColour(s) {
    var h = (s * 0.6180339887) % 1, sat = 0.75, v = 0.85;
    var f = function (o) {
      var c = (o + h * 6) % 6;
      return v - v * sat * Math.max(0, Math.min(c, 4 - c, 1));
    };
    return [f(5), f(3), f(1)];
  }

  // ---- the panel ----
  function el(tag, text, cls) {
    var e = document.createElement(tag);
    if (text !== undefined) e.textContent = text;
    if (cls) e.className = cls;
    return e;
  }
  function fmt(x, digits) { return x === null || x === undefined ? "–" : x.toFixed(digits); }
  function count(x) { return x.toLocaleString("en"); }
  document.title = "rgm: " + data.title;
  document.getElementById("title").textContent = data.title;
  var info = document.getElementById("info");
  function modelPanel() {
    var placed = model.scans.filter(function (scan) { return scan.inModel > 0; }).length;
    info.appendChild(el("div", placed + " of " + model.scans.length + " scans in the model",
      placed < model.scans.length ? "bad" : ""));
    var table = el("table");
    var head = el("tr");
    ["scan", "points", "in the model"].forEach(function (h) { head.appendChild(el("th", h)); });
    table.appendChild(head);
    model.scans.forEach(function (scan, s) {
      var tr = el("tr");
      var name = el("td");
      var dot = el("span", "", "swatch");
      dot.style.background = "rgb(" + scanColour(s).map(function (x) { return Math.round(255 * x); }).join(",") + ")";
      name.appendChild(dot);
      // The file's name, its whole path on hover.
      name.appendChild(document.createTextNode(scan.name.split(/[\\/]/).pop()));
      name.title = scan.name;
      tr.appendChild(name);
      tr.appendChild(el("td", count(scan.points)));
      tr.appendChild(el("td", scan.inModel > 0 ? count(scan.inModel) : "not placed"));
      table.appendChild(tr);
    });
    info.appendChild(table);
    info.appendChild(el("div", "points shown: the model " + count(model.shown) + " of " +
      count(model.points) + ", the scans as given " + count(model.given.shown) +
      " (thinned by a fixed stride to the page's budget of " + count(data.budget) + " points).", "note"));
  }
  function pairPanel() {
    var status = el("div", data.doubt ? "not registered: " + data.doubt : "registered by " + data.method,
      data.doubt ? "bad" : "");
    info.appendChild(status);
    var matrix = el("table", undefined, "matrix");
    data.transform.forEach(function (row) {
      var tr = el("tr");
      row.forEach(function (x) { tr.appendChild(el("td", x.toFixed(6))); });
      matrix.appendChild(tr);
    });
    info.appendChild(el("div", "transform target ← source (y = R x + t):", "note"));
    info.appendChild(matrix);
    if (data.fitness !== null) {
      info.appendChild(el("div", "fitness " + fmt(data.fitness, 4) + ", inlier RMSE " +
        fmt(data.inlierRmse, 6) + ", time " + fmt(data.timeMs, 1) + " ms", "note"));
    }
    if (data.candidates.length > 0) {
      var table = el("table");
      var head = el("tr");
      ["candidate", "score", "ms", "taken"].forEach(function (h) { head.appendChild(el("th", h)); });
      table.appendChild(head);
      data.candidates.forEach(function (c) {
        var tr = el("tr");
        tr.appendChild(el("td", c.method));
        tr.appendChild(el("td", c.failure ? "failed" : fmt(c.score, 4)));
        tr.appendChild(el("td", fmt(c.timeMs, 1)));
        tr.appendChild(el("td", c.chosen ? "✓" : ""));
        if (c.failure) tr.title = c.failure;
        table.appendChild(tr);
      });
      info.appendChild(table);
    }
    var within = 0;
    for (var i = 0; i < n; i++) within += inlier[i];
    info.appendChild(el("div", "source points within " + data.inlierDistance.toPrecision(4) +
      " of the target after the transform: " + count(within) + " of " + count(n) + " shown (" +
      fmt(100 * within / Math.max(n, 1), 1) + " %); the distance is " + data.inlierWhy + ".", "note"));
    var thinned = data.source.shown < data.source.points || data.target.shown < data.target.points;
    info.appendChild(el("div", "points shown: source " + count(data.source.shown) + " of " +
      count(data.source.points) + ", target " + count(data.target.shown) + " of " +
      count(data.target.points) + (thinned ? " — thinned by a fixed stride to the page's budget of " +
      count(data.budget) + " points (rgm: --html-points)" : " (all)") + ".", "note"));
    var c = data.correspondences;
    info.appendChild(el("div", "correspondences: " + (c.total > 0 ? c.note + ", " + count(c.shown) +
      " of " + count(c.total) + " drawn" : c.note) + ".", "note"));
  }
  if (model) modelPanel(); else pairPanel();
  var toggle = document.getElementById("toggle");
  var colourBox = document.getElementById("colour");
  var linesBox = document.getElementById("lines");
  var sizeSlider = document.getElementById("size");
  linesBox.disabled = k === 0;
  if (model) {
    colourBox.parentNode.hidden = true;
    linesBox.parentNode.hidden = true;
  }
  var legend = document.getElementById("legend");
  function swatch(colour, text) {
    var s = el("span", "", "swatch");
    s.style.background = "rgb(" + colour.map(function (x) { return Math.round(255 * x); }).join(",") + ")";
    legend.appendChild(s);
    legend.appendChild(document.createTextNode(text + "  "));
  }

  // ---- WebGL ----
  var canvas = document.getElementById("view");
  var gl = canvas.getContext("webgl", { antialias: false, preserveDrawingBuffer: selftest });
  if (!gl) throw new Error("this browser gives no WebGL context; the viewer needs WebGL");

  var VERTEX = [
    "attribute vec3 position;",
    "attribute float kind;",
    "attribute vec3 paint;",
    "uniform mat4 viewProjection;",
    "uniform mat4 after;",
    "uniform float pointSize;",
    "uniform float byDistance;",
    "uniform vec3 sourceColour, inlierColour, outlierColour, targetColour, lineColour;",
    "varying vec3 colour;",
    "void main() {",
    "  bool moves = kind < 1.5 || (kind > 2.5 && kind < 3.5);",
    "  vec4 p = moves ? after * vec4(position, 1.0) : vec4(position, 1.0);",
    "  gl_Position = viewProjection * p;",
    "  gl_PointSize = pointSize;",
    "  if (kind < 0.5) colour = mix(sourceColour, outlierColour, byDistance);",
    "  else if (kind < 1.5) colour = mix(sourceColour, inlierColour, byDistance);",
    "  else if (kind < 2.5) colour = targetColour;",
    "  else if (kind < 4.5) colour = lineColour;",
    "  else colour = paint;",
    "}",
  ].join("\n");
  var FRAGMENT = [
    "precision mediump float;",
    "uniform float round;",
    "varying vec3 colour;",
    "void main() {",
    "  if (round > 0.5 && length(gl_PointCoord - 0.5) > 0.5) discard;",
    "  gl_FragColor = vec4(colour, 1.0);",
    "}",
  ].join("\n");
  function shader(type, text) {
    var s = gl.createShader(type);
    gl.shaderSource(s, text);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(s));
    return s;
  }
  var program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
  // `position` at location 0, always an array: some drivers draw nothing when attribute 0 is
  // not one (a pair page leaves `paint` off).
  gl.bindAttribLocation(program, 0, "position");
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error("link: " + gl.getProgramInfoLog(program));
  gl.useProgram(program);
  var uniform = {};
  ["viewProjection", "after", "pointSize", "byDistance", "round", "sourceColour", "inlierColour",
    "outlierColour", "targetColour", "lineColour"].forEach(function (name) {
    uniform[name] = gl.getUniformLocation(program, name);
  });
  var positionAttribute = gl.getAttribLocation(program, "position");
  var kindAttribute = gl.getAttribLocation(program, "kind");
  var paintAttribute = gl.getAttribLocation(program, "paint");
  gl.uniform3fv(uniform.sourceColour, COLOURS.source);
  gl.uniform3fv(uniform.inlierColour, COLOURS.inlier);
  gl.uniform3fv(uniform.outlierColour, COLOURS.outlier);
  gl.uniform3fv(uniform.targetColour, COLOURS.target);
  gl.uniform3fv(uniform.lineColour, COLOURS.line);

  // One buffer pair (positions, kinds) per draw: the clouds, then the lines; a model's clouds
  // also carry each point's colour (`paint`, by its scan).
  function buffers(parts, scans) {
    var total = 0;
    parts.forEach(function (p) { total += p.xyz.length / 3; });
    var xyz = new Float32Array(3 * total); // (total, 3)
    var kinds = new Float32Array(total); // (total,)
    var at = 0;
    parts.forEach(function (p) {
      xyz.set(p.xyz, 3 * at);
      for (var i = 0; i < p.xyz.length / 3; i++) kinds[at + i] = p.kind(i);
      at += p.xyz.length / 3;
    });
    var position = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, position);
    gl.bufferData(gl.ARRAY_BUFFER, xyz, gl.STATIC_DRAW);
    var kind = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, kind);
    gl.bufferData(gl.ARRAY_BUFFER, kinds, gl.STATIC_DRAW);
    var paint = null;
    if (scans) {
      var colours = new Float32Array(3 * total); // (total, 3)
      for (var v = 0; v < total; v++) colours.set(scanColour(scans[v]), 3 * v);
      paint = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, paint);
      gl.bufferData(gl.ARRAY_BUFFER, colours, gl.STATIC_DRAW);
    }
    return { position: position, kind: kind, paint: paint, count: total };
  }
  var scanKind = function () { return KIND.scan; };
  // A model's two states are two clouds: the merged model and the scans as given.
  var clouds = model ? buffers([{ xyz: targetXyz, kind: scanKind }], scansOf(model.scan)) : buffers([
    { xyz: sourceXyz, kind: function (i) { return inlier[i] ? KIND.inlier : KIND.outlier; } },
    { xyz: targetXyz, kind: function () { return KIND.target; } },
  ]);
  var given = model ? buffers([{ xyz: sourceXyz, kind: scanKind }], scansOf(model.given.scan)) : null;
  // Lines as (source end, target end) vertex pairs.
  var lineXyz = new Float32Array(6 * k); // (k, 2, 3)
  for (var l = 0; l < k; l++) {
    lineXyz.set(lineSource.subarray(3 * l, 3 * l + 3), 6 * l);
    lineXyz.set(lineTarget.subarray(3 * l, 3 * l + 3), 6 * l + 3);
  }
  var lines = buffers([
    { xyz: lineXyz, kind: function (i) { return i % 2 === 0 ? KIND.lineSource : KIND.lineTarget; } },
  ]);
  function bind(b) {
    gl.bindBuffer(gl.ARRAY_BUFFER, b.position);
    gl.enableVertexAttribArray(positionAttribute);
    gl.vertexAttribPointer(positionAttribute, 3, gl.FLOAT, false, 0, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, b.kind);
    gl.enableVertexAttribArray(kindAttribute);
    gl.vertexAttribPointer(kindAttribute, 1, gl.FLOAT, false, 0, 0);
    if (paintAttribute < 0) return; // compiled out where no vertex reads it
    if (b.paint) {
      gl.bindBuffer(gl.ARRAY_BUFFER, b.paint);
      gl.enableVertexAttribArray(paintAttribute);
      gl.vertexAttribPointer(paintAttribute, 3, gl.FLOAT, false, 0, 0);
    } else {
      gl.disableVertexAttribArray(paintAttribute);
    }
  }

  // ---- the camera: orbiting `centre` at `distance`, z up ----
  var IDENTITY = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
  var FIELD_OF_VIEW = Math.PI / 4; // vertical
  // The view's centre, the target's per-axis median, and the radius about it that holds nearly
  // everything drawn (the target and the source before and after): its 99.5th percentile, so
  // a scanner's stray return far away does not shrink the view to a dot (zoom out to see it).
  function median(values) {
    var sorted = Float32Array.from(values).sort();
    return sorted[Math.floor(sorted.length / 2)];
  }
  var home = [0, 1, 2].map(function (axis) {
    return median(targetXyz.filter(function (_, i) { return i % 3 === axis; }));
  });
  var A = model ? IDENTITY : data.after;
  var norms = new Float32Array(m + 2 * n); // (m + 2n,) distances from `home`
  var away = function (x, y, z) { return Math.hypot(x - home[0], y - home[1], z - home[2]); };
  for (var t = 0; t < m; t++) norms[t] = away(targetXyz[3 * t], targetXyz[3 * t + 1], targetXyz[3 * t + 2]);
  for (var s = 0; s < n; s++) {
    var x = sourceXyz[3 * s], y = sourceXyz[3 * s + 1], z = sourceXyz[3 * s + 2];
    norms[m + 2 * s] = away(x, y, z);
    norms[m + 2 * s + 1] = away(A[0] * x + A[4] * y + A[8] * z + A[12],
      A[1] * x + A[5] * y + A[9] * z + A[13], A[2] * x + A[6] * y + A[10] * z + A[14]);
  }
  norms.sort();
  var reach = norms[Math.floor(0.995 * (norms.length - 1))];
  var camera;
  function resetCamera() {
    var aspect = Math.min(1, (canvas.clientWidth || 1) / (canvas.clientHeight || 1));
    var half = Math.atan(Math.tan(FIELD_OF_VIEW / 2) * aspect); // the narrower half-angle
    camera = { centre: home.slice(), distance: 1.05 * Math.max(reach, 1e-3) / Math.sin(half),
      azimuth: Math.PI / 4, elevation: Math.PI / 6 };
  }
  resetCamera();
  var state = { after: location.hash.indexOf("before") < 0 }; // `#before`: open on the clouds as given

  function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function normalise(a) { var s = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / s, a[1] / s, a[2] / s]; }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  // The camera's axes: towards it, right and up.
  function axes() {
    var ce = Math.cos(camera.elevation);
    var back = [ce * Math.cos(camera.azimuth), ce * Math.sin(camera.azimuth), Math.sin(camera.elevation)];
    var right = normalise(cross([0, 0, 1], back));
    return { back: back, right: right, up: cross(back, right) };
  }
  // projection · view, column after column.
  function viewProjection() {
    var a = axes();
    var eye = [0, 1, 2].map(function (i) { return camera.centre[i] + camera.distance * a.back[i]; });
    var near = camera.distance / 100, far = camera.distance + 2 * norms[norms.length - 1] + 1;
    var f = 1 / Math.tan(FIELD_OF_VIEW / 2);
    var aspect = canvas.width / canvas.height;
    var tx = -dot(a.right, eye), ty = -dot(a.up, eye), tz = -dot(a.back, eye);
    var p0 = f / aspect, p5 = f, p10 = (far + near) / (near - far), p14 = 2 * far * near / (near - far);
    var r = a.right, u = a.up, b = a.back;
    return [
      p0 * r[0], p5 * u[0], p10 * b[0], -b[0],
      p0 * r[1], p5 * u[1], p10 * b[1], -b[1],
      p0 * r[2], p5 * u[2], p10 * b[2], -b[2],
      p0 * tx, p5 * ty, p10 * tz + p14, -tz,
    ];
  }

  function resize() {
    var ratio = window.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(canvas.clientWidth * ratio));
    canvas.height = Math.max(1, Math.round(canvas.clientHeight * ratio));
  }

  function draw() {
    resize();
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(BACKGROUND[0], BACKGROUND[1], BACKGROUND[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.uniformMatrix4fv(uniform.viewProjection, false, viewProjection());
    gl.uniformMatrix4fv(uniform.after, false, state.after ? A : IDENTITY);
    gl.uniform1f(uniform.pointSize, Number(sizeSlider.value) * (window.devicePixelRatio || 1));
    gl.uniform1f(uniform.byDistance, state.after && colourBox.checked ? 1 : 0);
    gl.uniform1f(uniform.round, 1);
    var drawn = model && !state.after ? given : clouds;
    bind(drawn);
    gl.drawArrays(gl.POINTS, 0, drawn.count);
    if (linesBox.checked && k > 0) {
      gl.uniform1f(uniform.round, 0);
      bind(lines);
      gl.drawArrays(gl.LINES, 0, lines.count);
    }
  }
  var pending = false;
  function redraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(function () { pending = false; draw(); });
  }

  function showState() {
    legend.textContent = "";
    if (model) {
      toggle.textContent = state.after ? "merged ▸ show as given" : "as given ▸ show merged";
      legend.appendChild(document.createTextNode(state.after ? "the merged model, a colour per scan" :
        "each scan in its own frame, as given"));
      return;
    }
    toggle.textContent = state.after ? "after ▸ show before" : "before ▸ show after";
    if (state.after && colourBox.checked) {
      swatch(COLOURS.inlier, "source within " + data.inlierDistance.toPrecision(3));
      swatch(COLOURS.outlier, "source farther");
    } else {
      swatch(COLOURS.source, "source");
    }
    swatch(COLOURS.target, "target");
    if (linesBox.checked && k > 0) swatch(COLOURS.line, "correspondence");
    legend.appendChild(document.createTextNode(state.after ? "(after the transform)" : "(before it)"));
  }
  toggle.addEventListener("click", function () { state.after = !state.after; showState(); redraw(); });
  colourBox.addEventListener("change", function () { showState(); redraw(); });
  linesBox.addEventListener("change", function () { showState(); redraw(); });
  sizeSlider.addEventListener("input", redraw);
  document.getElementById("reset").addEventListener("click", function () { resetCamera(); redraw(); });
  window.addEventListener("resize", redraw);

  // ---- mouse and touch ----
  var pointers = new Map(); // pointer id → its last (x, y)
  var gesture = null; // for two pointers: their last distance and midpoint
  function orbit(dx, dy) {
    camera.azimuth -= dx * 0.01;
    camera.elevation = Math.max(-1.55, Math.min(1.55, camera.elevation + dy * 0.01));
  }
  function pan(dx, dy) {
    var a = axes();
    var s = camera.distance / canvas.clientHeight;
    for (var i = 0; i < 3; i++) camera.centre[i] += s * (-dx * a.right[i] + dy * a.up[i]);
  }
  function zoom(factor) { camera.distance = Math.max(0.001, Math.min(1000, camera.distance * factor)); }
  function twoPointers() {
    var p = Array.from(pointers.values());
    return { distance: Math.hypot(p[0].x - p[1].x, p[0].y - p[1].y), x: (p[0].x + p[1].x) / 2, y: (p[0].y + p[1].y) / 2 };
  }
  canvas.addEventListener("pointerdown", function (e) {
    canvas.setPointerCapture(e.pointerId);
    pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, panning: e.button === 2 || e.shiftKey });
    gesture = pointers.size === 2 ? twoPointers() : null;
  });
  canvas.addEventListener("pointermove", function (e) {
    var last = pointers.get(e.pointerId);
    if (!last) return;
    var dx = e.clientX - last.x, dy = e.clientY - last.y;
    last.x = e.clientX;
    last.y = e.clientY;
    if (pointers.size === 1) {
      if (last.panning) pan(dx, dy); else orbit(dx, dy);
    } else if (pointers.size === 2 && gesture) {
      var now = twoPointers();
      if (now.distance > 0 && gesture.distance > 0) zoom(gesture.distance / now.distance);
      pan(now.x - gesture.x, now.y - gesture.y);
      gesture = now;
    }
    redraw();
  });
  function release(e) {
    pointers.delete(e.pointerId);
    gesture = pointers.size === 2 ? twoPointers() : null;
  }
  canvas.addEventListener("pointerup", release);
  canvas.addEventListener("pointercancel", release);
  canvas.addEventListener("contextmenu", function (e) { e.preventDefault(); });
  canvas.addEventListener("wheel", function (e) {
    e.preventDefault();
    zoom(Math.exp(e.deltaY * 0.001));
    redraw();
  }, { passive: false });

  showState();
  draw();

  // ---- the self-test: both states drawn and read back ----
  if (selftest) {
    var pixels = function () {
      var out = new Uint8Array(canvas.width * canvas.height * 4);
      gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, out);
      return out;
    };
    var painted = function (p) {
      var count = 0;
      for (var i = 0; i < p.length; i += 4) if (p[i] < 250 || p[i + 1] < 250 || p[i + 2] < 250) count++;
      return count;
    };
    state.after = true;
    draw();
    var afterPixels = pixels();
    state.after = false;
    draw();
    var beforePixels = pixels();
    var changed = 0;
    for (var j = 0; j < afterPixels.length; j += 4) {
      if (afterPixels[j] !== beforePixels[j] || afterPixels[j + 1] !== beforePixels[j + 1] ||
          afterPixels[j + 2] !== beforePixels[j + 2]) changed++;
    }
    state.after = true;
    showState();
    draw();
    var verdict = {
      width: canvas.width, height: canvas.height,
      paintedAfter: painted(afterPixels), paintedBefore: painted(beforePixels), changed: changed,
      sourceShown: n, targetShown: m, errors: window.rgmErrors.length,
    };
    verdict.ok = verdict.paintedAfter > 100 && verdict.paintedBefore > 100 && changed > 100 &&
      verdict.errors === 0;
    var box = document.getElementById("selftest");
    box.hidden = false;
    box.textContent = "selftest " + JSON.stringify(verdict);
  }
})();
