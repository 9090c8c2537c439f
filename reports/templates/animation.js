// The body moving (reports/animation.py, report_animation): a box with the body's principal moments and its
// principal axes, turned by each run's quaternions, drawn on a canvas per run the reader picks (the
// reference first; each variant over the reference's box drawn faint and dashed). Data: the page's
// JSON element #anim-data (int16 base64), so the page works offline and self-contained.
(function () {
  "use strict";
  var el = document.getElementById("anim-data");
  if (!el) { return; }
  var D = JSON.parse(el.textContent);
  var n = D.t.length;
  function unpack(b64, scale) {
    if (!b64) { return null; }
    var bin = atob(b64), out = new Float64Array(bin.length / 2);
    for (var i = 0; i < out.length; i++) {
      var v = bin.charCodeAt(2 * i) | (bin.charCodeAt(2 * i + 1) << 8);
      if (v & 0x8000) { v -= 0x10000; }
      out[i] = v === -32768 ? NaN : v / scale;
    }
    return out;
  }
  var runs = {};
  D.runs.forEach(function (r) { runs[r.name] = {label: r.label, color: r.color, div: r.div,
    q: unpack(r.q, 32767), err: unpack(r.err, 100)}; });
  var el_ = D.camera[0] * Math.PI / 180, az = D.camera[1] * Math.PI / 180;
  var right = [-Math.sin(az), Math.cos(az), 0];
  var up = [-Math.sin(el_) * Math.cos(az), -Math.sin(el_) * Math.sin(az), Math.cos(el_)];
  var toward = [Math.cos(el_) * Math.cos(az), Math.cos(el_) * Math.sin(az), Math.sin(el_)];
  var A = D.axes, h = D.half;
  function bodyVec(c) {   // principal-axes coordinates -> body axes
    return [A[0][0] * c[0] + A[0][1] * c[1] + A[0][2] * c[2], A[1][0] * c[0] + A[1][1] * c[1] + A[1][2] * c[2],
            A[2][0] * c[0] + A[2][1] * c[1] + A[2][2] * c[2]];
  }
  var corners = [];
  for (var k = 0; k < 8; k++) {
    corners.push(bodyVec([(k & 1 ? 1 : -1) * h[0], (k & 2 ? 1 : -1) * h[1], (k & 4 ? 1 : -1) * h[2]]));
  }
  var hn = Math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
  var hmax = Math.max(h[0], h[1], h[2]);   // as reports/animation.py axis_lengths
  var tips = [0, 1, 2].map(function (i) { var c = [0, 0, 0]; c[i] = Math.max(1.45 * h[i], 0.75 * hmax);
                                          return bodyVec(c); });
  var FACES = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
  var AXIS = ["#d62728", "#2ca02c", "#1f77b4"];
  var extent = 1.05 * Math.max(hn, Math.max(1.45 * h[0], 1.45 * h[1], 1.45 * h[2], 0.75 * hmax));
  function quat(run, k) {
    var q = run.q;
    if (!q || !isFinite(q[4 * k])) { return null; }
    return [q[4 * k], q[4 * k + 1], q[4 * k + 2], q[4 * k + 3]];
  }
  function rot(q, v) {   // R(q) v, q = (w, x, y, z) body -> world
    var w = q[0], x = q[1], y = q[2], z = q[3];
    return [(1 - 2 * (y * y + z * z)) * v[0] + 2 * (x * y - w * z) * v[1] + 2 * (x * z + w * y) * v[2],
            2 * (x * y + w * z) * v[0] + (1 - 2 * (x * x + z * z)) * v[1] + 2 * (y * z - w * x) * v[2],
            2 * (x * z - w * y) * v[0] + 2 * (y * z + w * x) * v[1] + (1 - 2 * (x * x + y * y)) * v[2]];
  }
  function dot(a, b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
  function rgba(hex, a) {
    var v = parseInt(hex.slice(1), 16);
    return "rgba(" + (v >> 16 & 255) + "," + (v >> 8 & 255) + "," + (v & 255) + "," + a + ")";
  }
  function drawBox(ctx, W, H, q, color, ghost) {
    var s = Math.min(W, H * 1.15) / (2 * extent), cx = W / 2, cy = H / 2 + 8;
    var P = corners.map(function (c) { var p = rot(q, c); return [cx + s * dot(p, right), cy - s * dot(p, up),
                                                                   dot(p, toward)]; });
    var order = FACES.map(function (f, i) { return [f.reduce(function (a, j) { return a + P[j][2]; }, 0), i]; })
      .sort(function (a, b) { return a[0] - b[0]; });
    var axes = tips.map(function (t, i) { var p = rot(q, t); return [cx + s * dot(p, right), cy - s * dot(p, up),
                                                                      dot(p, toward), i]; });
    ctx.lineJoin = "round";
    if (!ghost) {   // axes pointing away first, then the faces, then the axes towards the viewer
      axes.filter(function (a) { return a[2] < 0; }).forEach(function (a) { line(ctx, cx, cy, a, AXIS[a[3]]); });
    }
    order.forEach(function (o) {
      var f = FACES[o[1]];
      ctx.beginPath();
      ctx.moveTo(P[f[0]][0], P[f[0]][1]);
      for (var j = 1; j < 4; j++) { ctx.lineTo(P[f[j]][0], P[f[j]][1]); }
      ctx.closePath();
      if (ghost) {
        ctx.setLineDash([4, 3]);
        ctx.strokeStyle = "rgba(120,120,120,0.7)";
        ctx.lineWidth = 1;
        ctx.stroke();
        ctx.setLineDash([]);
      } else {
        ctx.fillStyle = rgba(color, 0.32);
        ctx.fill();
        ctx.strokeStyle = "#333";
        ctx.lineWidth = 1;
        ctx.stroke();
      }
    });
    if (!ghost) {
      axes.filter(function (a) { return a[2] >= 0; }).forEach(function (a) { line(ctx, cx, cy, a, AXIS[a[3]]); });
    }
  }
  function line(ctx, cx, cy, a, color) {
    ctx.beginPath();
    ctx.moveTo(cx, cy);
    ctx.lineTo(a[0], a[1]);
    ctx.strokeStyle = color;
    ctx.lineWidth = 2.5;
    ctx.lineCap = "round";
    ctx.stroke();
  }
  var panels = document.getElementById("anim-panels");
  var slider = document.getElementById("anim-slider");
  var button = document.getElementById("anim-play");
  var clock = document.getElementById("anim-time");
  var shown = [];
  function build() {
    panels.textContent = "";
    shown = ["reference"];
    document.querySelectorAll("input.anim-pick:checked").forEach(function (c) { shown.push(c.value); });
    shown.forEach(function (name) {
      var fig = document.createElement("div");
      fig.className = "anim-panel";
      var cv = document.createElement("canvas");
      var r = window.devicePixelRatio || 1;
      cv.width = 300 * r;
      cv.height = 250 * r;
      cv.style.width = "300px";
      cv.style.height = "250px";
      cv.setAttribute("data-run", name);
      cv.setAttribute("role", "img");
      cv.setAttribute("aria-label", "the body turning: " + runs[name].label);
      fig.appendChild(cv);
      panels.appendChild(fig);
    });
    draw(frame);
  }
  var frame = 0;
  function draw(k) {
    frame = k;
    slider.value = k;
    clock.textContent = "t = " + D.t[k].toFixed(3) + " s";
    panels.querySelectorAll("canvas").forEach(function (cv) {
      var run = runs[cv.getAttribute("data-run")], ref = runs.reference;
      var r = window.devicePixelRatio || 1, ctx = cv.getContext("2d");
      ctx.setTransform(r, 0, 0, r, 0, 0);
      var W = 300, H = 250;
      ctx.clearRect(0, 0, W, H);
      ctx.fillStyle = "#fff";
      ctx.fillRect(0, 0, W, H);
      var kk = k, q = quat(run, k);
      while (!q && kk > 0) { kk -= 1; q = quat(run, kk); }   // diverged: its last frame before the divergence
      if (run !== ref) {
        var qr = quat(ref, k);
        if (qr) { drawBox(ctx, W, H, qr, "#8c8c8c", true); }
      }
      if (q) { drawBox(ctx, W, H, q, run.color, false); }
      ctx.fillStyle = "#222";
      ctx.font = "12px sans-serif";
      ctx.fillText(run.label, 6, 15);
      ctx.font = "11px monospace";
      if (run.err) {
        var e = run.err[kk];
        ctx.fillText("error " + (isFinite(e) ? e.toFixed(1) + "°" : "–"), 6, 30);
      }
      if (run.div !== null && kk < k) {
        ctx.fillStyle = "#a00";
        ctx.font = "bold 12px sans-serif";
        ctx.fillText("diverged at t = " + run.div.toPrecision(4) + " s", 6, H - 8);
      }
    });
  }
  var playing = !window.matchMedia("(prefers-reduced-motion: reduce)").matches, last = 0;
  function tick(ts) {
    if (playing && ts - last >= 1000 / D.fps) {
      last = ts;
      draw((frame + 1) % n);
    }
    window.requestAnimationFrame(tick);
  }
  button.textContent = playing ? "pause" : "play";
  button.addEventListener("click", function () {
    playing = !playing;
    button.textContent = playing ? "pause" : "play";
  });
  slider.addEventListener("input", function () { playing = false; button.textContent = "play";
                                                 draw(parseInt(slider.value, 10)); });
  document.querySelectorAll("input.anim-pick").forEach(function (c) { c.addEventListener("change", build); });
  build();
  window.requestAnimationFrame(tick);
}());
