// polishbot's offline 3D viewer: a software point renderer on a 2D canvas (depth buffer and
// per-pixel point index in typed arrays), so it needs no WebGL, no GPU and no network. Reads
// window.POLISHBOT_VIEWER (viewer-data.js beside the page: base64 typed arrays).
// Drag: rotate; shift-drag or right-drag: pan; wheel: zoom; hover: read a point.
(function () {
  'use strict';
  var D = window.POLISHBOT_VIEWER;
  var root = document.getElementById('viewer');
  var check = document.getElementById('viewer-check');
  function fail(msg) {
    check.setAttribute('data-ok', 'false');
    check.textContent = 'viewer self-check failed: ' + msg;
  }
  if (!D) { fail('viewer-data.js did not load'); return; }
  function bytes(b64) {
    var s = atob(b64), n = s.length, out = new Uint8Array(n);
    for (var i = 0; i < n; i++) out[i] = s.charCodeAt(i);
    return out.buffer;
  }
  var n = D.n;
  var qpos = new Uint16Array(bytes(D.pos));
  var qnrm = new Int8Array(bytes(D.nrm));
  var dev = new Float32Array(bytes(D.dev));
  var unc = new Float32Array(bytes(D.unc));
  var lab = new Int16Array(bytes(D.lab));
  var pos = new Float32Array(3 * n), nrm = new Float32Array(3 * n);
  for (var i = 0; i < 3 * n; i++) {
    var a = i % 3;
    pos[i] = D.origin[a] + qpos[i] * D.step[a];
    nrm[i] = qnrm[i] / 127;
  }
  var canvas = root.querySelector('canvas');
  var ctx = canvas.getContext('2d');
  var W = canvas.width, H = canvas.height;
  var img = ctx.createImageData(W, H);
  var depth = new Float32Array(W * H), idx = new Int32Array(W * H);
  var rgb = new Uint8Array(3 * n);
  var tolInput = root.querySelector('[name=tolerance]');
  var rangeInput = root.querySelector('[name=range]');
  var info = root.querySelector('.viewer-info');
  // Colour map: ColorBrewer RdBu stops as in the figures; inside the tolerance band a flat
  // pale green, no value grey.
  var STOPS = [[-1, 5, 48, 97], [-0.6, 67, 147, 195], [-0.25, 209, 229, 240], [0, 247, 247, 247],
    [0.25, 253, 219, 199], [0.6, 214, 96, 77], [1, 103, 0, 31]];
  function colour(v, tol, range, out, k) {
    if (!isFinite(v)) { out[k] = 180; out[k + 1] = 180; out[k + 2] = 180; return; }
    if (Math.abs(v) <= tol) { out[k] = 200; out[k + 1] = 230; out[k + 2] = 200; return; }
    var t = Math.max(-1, Math.min(1, v / range)), j = 0;
    while (j < STOPS.length - 2 && t > STOPS[j + 1][0]) j++;
    var s0 = STOPS[j], s1 = STOPS[j + 1], f = (t - s0[0]) / (s1[0] - s0[0]);
    for (var c = 1; c < 4; c++) out[k + c - 1] = Math.round(s0[c] + (s1[c] - s0[c]) * f);
  }
  var outside = 0;
  function recolour() {
    var tol = Math.max(0, parseFloat(tolInput.value) || 0);
    var range = Math.max(1e-6, parseFloat(rangeInput.value) || D.range);
    outside = 0;
    for (var i = 0; i < n; i++) {
      colour(dev[i], tol, range, rgb, 3 * i);
      if (Math.abs(dev[i]) > tol) outside++;
    }
  }
  // View: rotation R (row-major 3x3), zoom (px per mm), pan (px).
  var R = [1, 0, 0, 0, 0, 1, 0, -1, 0], pan = [0, 0], zoom = 1;
  var c0 = D.centre;
  function fit() {
    zoom = 0.8 * Math.min(W, H) / D.extent;
    pan = [0, 0];
  }
  function rotate(ax, ay) {
    // Screen-axis rotations (about screen y by ax, about screen x by ay), applied after R.
    var cy = Math.cos(ax), sy = Math.sin(ax), cx = Math.cos(ay), sx = Math.sin(ay);
    var Ry = [cy, 0, sy, 0, 1, 0, -sy, 0, cy], Rx = [1, 0, 0, 0, cx, -sx, 0, sx, cx];
    R = mul(Rx, mul(Ry, R));
  }
  function mul(A, B) {
    var C = new Array(9);
    for (var r = 0; r < 3; r++) for (var c = 0; c < 3; c++)
      C[3 * r + c] = A[3 * r] * B[c] + A[3 * r + 1] * B[3 + c] + A[3 * r + 2] * B[6 + c];
    return C;
  }
  var drawn = 0;
  function render(stride) {
    var data = img.data, splat = Math.max(1, Math.min(10, Math.ceil(zoom * D.spacing * 2.5)));
    depth.fill(-Infinity); idx.fill(-1);
    for (var k = 0; k < data.length; k += 4) { data[k] = 255; data[k + 1] = 255; data[k + 2] = 255; data[k + 3] = 255; }
    var h = splat >> 1, cxp = W / 2 + pan[0], cyp = H / 2 + pan[1];
    for (var i = 0; i < n; i += stride) {
      var nx = nrm[3 * i], ny = nrm[3 * i + 1], nz = nrm[3 * i + 2];
      var tz = R[6] * nx + R[7] * ny + R[8] * nz;
      if (tz < 0) continue;
      var x = pos[3 * i] - c0[0], y = pos[3 * i + 1] - c0[1], z = pos[3 * i + 2] - c0[2];
      var sx = Math.round(cxp + zoom * (R[0] * x + R[1] * y + R[2] * z));
      var sy = Math.round(cyp - zoom * (R[3] * x + R[4] * y + R[5] * z));
      var d = R[6] * x + R[7] * y + R[8] * z;
      for (var py = Math.max(0, sy - h); py <= Math.min(H - 1, sy + h); py++)
        for (var px = Math.max(0, sx - h); px <= Math.min(W - 1, sx + h); px++) {
          var p = py * W + px;
          if (d > depth[p]) { depth[p] = d; idx[p] = i; }
        }
    }
    drawn = 0;
    for (var p = 0; p < W * H; p++) {
      var j = idx[p];
      if (j < 0) continue;
      drawn++;
      var tz2 = R[6] * nrm[3 * j] + R[7] * nrm[3 * j + 1] + R[8] * nrm[3 * j + 2];
      var s = 0.35 + 0.65 * Math.max(0, Math.min(1, tz2));
      data[4 * p] = rgb[3 * j] * s; data[4 * p + 1] = rgb[3 * j + 1] * s; data[4 * p + 2] = rgb[3 * j + 2] * s;
    }
    ctx.putImageData(img, 0, 0);
    labels();
  }
  function labels() {
    ctx.font = 'bold 14px sans-serif';
    ctx.textBaseline = 'middle';
    D.regions.forEach(function (r) {
      var q = r.normal, tz = R[6] * q[0] + R[7] * q[1] + R[8] * q[2];
      if (tz < 0.2) return;
      var x = r.centroid[0] - c0[0], y = r.centroid[1] - c0[1], z = r.centroid[2] - c0[2];
      var sx = W / 2 + pan[0] + zoom * (R[0] * x + R[1] * y + R[2] * z);
      var sy = H / 2 + pan[1] - zoom * (R[3] * x + R[4] * y + R[5] * z);
      ctx.strokeStyle = '#000'; ctx.fillStyle = '#fff'; ctx.lineWidth = 2;
      ctx.beginPath(); ctx.moveTo(sx, sy); ctx.lineTo(sx + 18, sy - 18); ctx.stroke();
      ctx.beginPath(); ctx.arc(sx + 18, sy - 18, 11, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      ctx.fillStyle = '#000'; ctx.textAlign = 'center'; ctx.fillText(String(r.id), sx + 18, sy - 18);
    });
  }
  var FAST = Math.max(1, Math.ceil(n / 150000)), pending = 0;
  function full() { clearTimeout(pending); pending = setTimeout(function () { render(1); }, 120); }
  var drag = null;
  canvas.addEventListener('contextmenu', function (e) { e.preventDefault(); });
  canvas.addEventListener('mousedown', function (e) { drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 }; });
  window.addEventListener('mouseup', function () { if (drag) { drag = null; full(); } });
  canvas.addEventListener('mousemove', function (e) {
    if (drag) {
      var dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) { pan[0] += dx; pan[1] += dy; } else rotate(dx * 0.01, dy * 0.01);
      render(FAST);
      return;
    }
    var b = canvas.getBoundingClientRect();
    var px = Math.floor((e.clientX - b.left) * W / b.width), py = Math.floor((e.clientY - b.top) * H / b.height);
    var j = (px >= 0 && py >= 0 && px < W && py < H) ? idx[py * W + px] : -1;
    info.textContent = j < 0 ? 'hover a point to read it' : readout(j);
  });
  canvas.addEventListener('wheel', function (e) {
    e.preventDefault();
    zoom *= Math.exp(-e.deltaY * 0.001);
    render(FAST); full();
  }, { passive: false });
  function readout(j) {
    var f = function (v, d) { return isFinite(v) ? (v >= 0 ? '+' : '') + v.toFixed(d) : 'no value'; };
    return 'point ' + j + ' at (' + pos[3 * j].toFixed(2) + ', ' + pos[3 * j + 1].toFixed(2) + ', ' +
      pos[3 * j + 2].toFixed(2) + ') mm: deviation ' + f(dev[j], 4) + ' mm, uncertainty (LoD95) ' +
      (isFinite(unc[j]) ? unc[j].toFixed(4) + ' mm' : 'unknown') + (lab[j] >= 0 ? ', region ' + lab[j] : '');
  }
  root.querySelector('[name=reset]').addEventListener('click', function () { R = [1, 0, 0, 0, 0, 1, 0, -1, 0]; fit(); render(1); });
  function onBand() { recolour(); render(1); root.querySelector('.viewer-band').textContent = outside + ' of ' + n + ' points outside the band'; }
  tolInput.addEventListener('input', onBand);
  rangeInput.addEventListener('input', onBand);
  // Self-check: the arrays decoded to the promised lengths and values (count, NaNs, largest
  // |deviation| and region labels as the writer computed them) and the first frame drew.
  var t0 = performance.now();
  fit(); onBand();
  var nan = 0, maxAbs = 0, labelled = 0;
  for (var k = 0; k < n; k++) {
    if (!isFinite(dev[k])) nan++; else maxAbs = Math.max(maxAbs, Math.abs(dev[k]));
    if (lab[k] >= 0) labelled++;
  }
  var problems = [];
  [['positions', qpos.length, 3 * n], ['normals', qnrm.length, 3 * n], ['deviations', dev.length, n],
    ['uncertainties', unc.length, n], ['labels', lab.length, n]].forEach(function (c) {
    if (c[1] !== c[2]) problems.push(c[0] + ' ' + c[1] + ' != ' + c[2]);
  });
  if (nan !== D.check.nan) problems.push('no-value points ' + nan + ' != ' + D.check.nan);
  if (maxAbs !== D.check.max_abs) problems.push('max |deviation| ' + maxAbs + ' != ' + D.check.max_abs);
  if (labelled !== D.check.labelled) problems.push('labelled points ' + labelled + ' != ' + D.check.labelled);
  if (drawn === 0) problems.push('nothing drawn');
  check.setAttribute('data-points', n);
  check.setAttribute('data-drawn-px', drawn);
  check.setAttribute('data-ms', Math.round(performance.now() - t0));
  if (problems.length) { fail(problems.join('; ')); return; }
  check.setAttribute('data-ok', 'true');
  check.textContent = 'viewer self-check passed: ' + n + ' points decoded, ' + nan + ' without a value, max |deviation| ' +
    maxAbs.toFixed(4) + ' mm, ' + drawn + ' px drawn';
})();
