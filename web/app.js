/* app.js - the classroom page: controls, one Web Worker per setting, pictures, plot.
 *
 * Scheduling: each worker runs one pass at a time when asked.  At equal passes a
 * setting may start pass j + 1 only when no other setting is still before pass
 * j + 1 (lockstep, the settings run in parallel).  At equal time a setting may
 * start a pass while its time inside passes is at most the smallest of the
 * others plus its own last pass: the slower setting always runs, the faster one
 * waits, and the difference never exceeds one pass.
 *
 * A URL such as index.html?test=1&scene=CornellBox-Sphere&size=64&passes=16&seed=7
 * &methods=appm,ppm[&camera=scene] runs those settings to that pass count (with
 * the camera of the scene's .scene file) and leaves the result
 * in window.appmTest (tests/web.py reads it in headless Chromium).
 */
'use strict';

var SCENES = ['CornellBox-Sphere', 'CornellBox-Original', 'CornellBox-Mirror', 'CornellBox-Glossy',
              'CornellBox-Empty-RG', 'CornellBox-Empty-White'];
var METHODS = ['appm', 'appm-paper', 'ppm', 'sppm', 'pt'];
var RADII = [['0.25', '¼ ×'], ['0.5', '½ ×'], ['1', '1 ×'], ['2', '2 ×'], ['4', '4 ×']];
var COLOURS = ['#0057b8', '#d55e00', '#007a4d']; // blue, vermilion, green: distinct for colour-blind eyes
var MAP_NAMES = ['radius', 'variance', 'Laplacian'];

var PRESETS = [
  { name: 'ppm with a quarter of the automatic radius against appm (noise)', count: 2, equal: 'time',
    sides: [{ method: 'ppm', radius: '0.25' }, { method: 'appm' }] },
  { name: 'ppm with four times the automatic radius against appm (blur)', count: 2, equal: 'time',
    sides: [{ method: 'ppm', radius: '4' }, { method: 'appm' }] },
  { name: 'appm, ppm and sppm at equal passes', count: 3, equal: 'passes',
    sides: [{ method: 'appm' }, { method: 'ppm' }, { method: 'sppm' }] },
  { name: 'ppm with α = 1 (fixed radius, never converges) against α = 2/3', count: 2, equal: 'passes',
    sides: [{ method: 'ppm', alpha: '1' }, { method: 'ppm', alpha: '0.6667' }] },
  { name: 'the paper\'s adaptive radius (appm-paper) against appm with its extensions', count: 2, equal: 'passes',
    sides: [{ method: 'appm-paper' }, { method: 'appm' }] },
  { name: 'appm with the random sampler against the qmc (Sobol\') sampler', count: 2, equal: 'passes',
    sides: [{ method: 'appm', sampler: 'random' }, { method: 'appm', sampler: 'qmc' }] },
];

var $ = function (id) { return document.getElementById(id); };
var sceneCache = {};
var run = null;             // the current run: settings, sides, state
var params = new URLSearchParams(location.search);
var testMode = params.get('test') === '1';

/* ---- Controls ------------------------------------------------------------------ */

function option(sel, value, text, selected) {
  var o = document.createElement('option');
  o.value = value; o.textContent = text; o.selected = !!selected;
  sel.appendChild(o);
}

function sideControls(i) {
  var f = document.createElement('fieldset');
  f.className = 'sidectl';
  f.style.borderColor = COLOURS[i];
  f.innerHTML =
    '<legend style="color:' + COLOURS[i] + '">Setting ' + 'ABC'[i] + '</legend>' +
    '<label>Method <select name="method"></select></label>' +
    '<label>Sampler <select name="sampler"><option value="qmc" selected>qmc (Sobol\')</option>' +
    '<option value="random">random (PCG)</option></select></label>' +
    '<label>Initial radius <select name="radius"></select> automatic</label>' +
    '<label>α <input name="alpha" type="number" min="0.05" max="1" step="0.05" value="0.6667"></label>' +
    '<label>Photons per pass <input name="photons" type="number" min="0" step="1024" value="0">' +
    ' <span class="hint">(0: one per pixel)</span></label>';
  var m = f.querySelector('[name=method]'), r = f.querySelector('[name=radius]');
  METHODS.forEach(function (x) { option(m, x, x, x === ['appm', 'ppm', 'sppm'][i]); });
  RADII.forEach(function (x) { option(r, x[0], x[1], x[0] === '1'); });
  return f;
}

function buildControls() {
  SCENES.forEach(function (s) { option($('scene'), s, s, s === 'CornellBox-Sphere'); });
  PRESETS.forEach(function (p, i) { option($('preset'), String(i), (i + 1) + ': ' + p.name); });
  for (var i = 0; i < 3; ++i) $('sidecontrols').appendChild(sideControls(i));
  showSideControls();
}

function showSideControls() {
  var n = +$('count').value;
  Array.prototype.forEach.call(document.querySelectorAll('.sidectl'), function (f, i) {
    f.hidden = i >= n;
    f.disabled = i >= n;
  });
}

function applyPreset(i) {
  var p = PRESETS[i], ctl = document.querySelectorAll('.sidectl');
  $('preset').value = String(i);
  $('count').value = String(p.count);
  $('equal').value = p.equal;
  p.sides.forEach(function (s, k) {
    ctl[k].querySelector('[name=method]').value = s.method;
    ctl[k].querySelector('[name=radius]').value = s.radius || '1';
    ctl[k].querySelector('[name=alpha]').value = s.alpha || '0.6667';
    ctl[k].querySelector('[name=photons]').value = '0';
    ctl[k].querySelector('[name=sampler]').value = s.sampler || 'qmc';
  });
  showSideControls();
}

function readSettings() {
  var n = +$('count').value, size = +$('size').value, sides = [];
  var ctl = document.querySelectorAll('.sidectl');
  for (var i = 0; i < n; ++i) {
    var c = ctl[i], alpha = +c.querySelector('[name=alpha]').value;
    sides.push({
      method: c.querySelector('[name=method]').value,
      sampler: c.querySelector('[name=sampler]').value,
      radiusFactor: +c.querySelector('[name=radius]').value,
      alpha: alpha > 0 && alpha <= 1 ? alpha : 0,
      photons: Math.max(0, Math.floor(+c.querySelector('[name=photons]').value || 0)),
    });
  }
  var stop = Math.max(0, +$('stop').value || 0);
  return {
    scene: $('scene').value, sceneCamera: $('scenecam').checked, width: size, height: size,
    seed: Math.max(0, Math.floor(+$('seed').value || 0)),
    equal: $('equal').value,
    stopPasses: $('stopunit').value === 'passes' ? stop : 0,
    stopSeconds: $('stopunit').value === 'seconds' ? stop : 0,
    sides: sides,
  };
}

function describe(s) {
  var t = s.method;
  if (s.method !== 'pt' && s.radiusFactor !== 1) t += ', r₀ = ' + s.radiusFactor + ' × auto';
  if ((s.method === 'ppm' || s.method === 'sppm') && s.alpha) t += ', α = ' + (+s.alpha.toFixed(3));
  if (s.sampler === 'random') t += ', random sampler';
  if (s.photons) t += ', ' + s.photons + ' photons/pass';
  return t;
}

/* ---- Scenes -------------------------------------------------------------------- */

function fetchText(url) {
  return fetch(url).then(function (r) {
    if (!r.ok) throw new Error(url + ': HTTP ' + r.status + ' (run make web)');
    return r.text();
  });
}

// CornellBox-Empty-RG -> cornell-empty-rg.scene: the .scene file of scenes/ that frames
// the box with its own camera (the OBJ alone gets one framing its bounding sphere).
function sceneFile(name) { return 'cornell-' + name.replace(/^CornellBox-/, '').toLowerCase() + '.scene'; }

function loadScene(name) {
  if (sceneCache[name]) return Promise.resolve(sceneCache[name]);
  return Promise.all([fetchText('scenes/' + name + '.obj'), fetchText('scenes/' + name + '.mtl'),
                      fetchText('scenes/' + sceneFile(name))])
    .then(function (t) {
      return (sceneCache[name] = { obj: t[0], mtl: t[1], name: name + '.obj', scene: t[2] });
    });
}

/* ---- A run: workers and their schedule ------------------------------------------ */

function status(text) { $('status').textContent = text; }

function reportError(where, message) {
  console.error(where + ': ' + message);
  status('Error in ' + where + ': ' + message);
  if (run) run.running = false;
  if (testMode) window.appmTest = { done: true, error: where + ': ' + message };
}

function stopRun() {
  if (!run) return;
  run.sides.forEach(function (s) { s.worker.terminate(); });
  run = null;
}

function startRun() {
  var settings = readSettings();
  stopRun();
  $('plot').getContext('2d').clearRect(0, 0, $('plot').width, $('plot').height);
  var r = run = { settings: settings, sides: [], running: true, t0: performance.now() };
  $('pausebtn').firstChild.textContent = 'Pause ';
  buildSideViews(settings);
  status('Loading ' + settings.scene + ' ...');
  loadScene(settings.scene).then(function (scene) {
    if (run !== r) return;
    settings.sides.forEach(function (s, i) { r.sides.push(makeSide(r, i, s, scene)); });
    status('Rendering ' + settings.scene + ' at ' + settings.width + ' × ' + settings.height + ', equal ' +
           settings.equal + (settings.stopPasses ? ', ' + settings.stopPasses + ' passes' : '') +
           (settings.stopSeconds ? ', ' + settings.stopSeconds + ' s each' : '') + '.');
  }).catch(function (e) { reportError('scene', e.message); });
}

function makeSide(r, i, s, scene) {
  var w = new Worker('worker.js');
  var side = { index: i, settings: s, worker: w, started: false, busy: true, done: false,
               stats: null, lastPass: 0, lastPictures: 0, history: [], view: r.views[i] };
  w.onmessage = function (e) { if (run === r) onWorkerMessage(r, side, e.data); };
  w.onerror = function (e) { if (run === r) reportError('worker ' + 'ABC'[i], e.message || 'failed'); };
  if (r.settings.sceneCamera)
    w.postMessage({ type: 'load', scene: scene.scene, sceneName: sceneFile(r.settings.scene), obj: scene.obj,
                    objName: scene.name, mtl: scene.mtl, mtlName: r.settings.scene + '.mtl' });
  else
    w.postMessage({ type: 'load', obj: scene.obj, mtl: scene.mtl, name: scene.name });
  w.postMessage({ type: 'start', opts: { method: s.method, sampler: s.sampler, width: r.settings.width,
    height: r.settings.height, photons: s.photons, radiusFactor: s.radiusFactor, alpha: s.alpha,
    seed: r.settings.seed } });
  return side;
}

function onWorkerMessage(r, side, m) {
  switch (m.type) {
  case 'ready': case 'loaded': return;
  case 'error': reportError('setting ' + 'ABC'[side.index], m.message); return;
  case 'started':
    side.started = true; side.busy = false; side.stats = m.stats;
    break;
  case 'passed':
    side.busy = false;
    side.lastPass = m.stats.seconds - (side.stats ? side.stats.seconds : 0);
    side.stats = m.stats;
    if (m.stats.error > 0) side.history.push([m.stats.photons || m.stats.eyePaths, m.stats.error, m.stats.noiseOnly]);
    if (m.pictures) drawPictures(side, m.pictures);
    drawStats(side);
    schedulePlot();
    if (finished(r, side)) {
      side.done = true;
      side.busy = true;
      side.worker.postMessage({ type: 'snapshot', linear: testMode, exposure: exposure() });
    }
    break;
  case 'snapshot':
    side.busy = false;
    drawPictures(side, m.pictures);
    drawStats(side);
    if (m.linear) side.linear = m.linear;
    if (!r.finished && r.sides.every(function (s) { return s.done && !s.busy; })) finishRun(r);
    break;
  }
  schedule(r);
}

function finished(r, side) {
  var st = side.stats, s = r.settings;
  return (s.stopPasses > 0 && st.passes >= s.stopPasses) || (s.stopSeconds > 0 && st.seconds >= s.stopSeconds);
}

// Hands out the next passes (see the top of the file for the rule).
function schedule(r) {
  if (!r.running && !r.stepping) return;
  if (!r.sides.length || !r.sides.every(function (s) { return s.started; })) return;
  var live = r.sides.filter(function (s) { return !s.done; });
  if (!live.length) return;
  var minPasses = Math.min.apply(null, live.map(function (s) { return s.stats.passes; }));
  var minSeconds = Math.min.apply(null, live.map(function (s) { return s.stats.seconds; }));
  var now = performance.now();
  live.forEach(function (s) {
    if (s.busy) return;
    var ok = r.settings.equal === 'passes' ? s.stats.passes <= minPasses
                                           : s.stats.seconds <= minSeconds + s.lastPass;
    if (r.stepping) ok = s.stats.passes < s.stepTarget;
    if (!ok) return;
    var pics = now - s.lastPictures > 150 || r.stepping;
    if (pics) s.lastPictures = now;
    s.busy = true;
    s.worker.postMessage({ type: 'pass', pictures: pics, exposure: exposure() });
  });
  if (r.stepping && live.every(function (s) { return !s.busy && s.stats.passes >= s.stepTarget; }))
    r.stepping = false;
}

function finishRun(r) {
  r.running = false;
  r.finished = true;
  status('Done: ' + r.sides.map(function (s) {
    return describe(s.settings) + ' ' + s.stats.passes + ' passes in ' + s.stats.seconds.toFixed(2) + ' s';
  }).join('; ') + '.');
  if (testMode) window.appmTest = testResult(r);
}

function togglePause() {
  if (!run) return;
  if (run.sides.length && run.sides.every(function (s) { return s.done; })) return;
  run.running = !run.running;
  $('pausebtn').firstChild.textContent = run.running ? 'Pause ' : 'Resume ';
  status(run.running ? 'Running.' : 'Paused (N: one more pass).');
  schedule(run);
}

function stepOnce() {
  if (!run || run.running || !run.sides.length) return;
  if (run.stepping || !run.sides.every(function (s) { return s.started; })) return;
  run.sides.forEach(function (s) { s.stepTarget = s.stats.passes + (s.done ? 0 : 1); });
  run.stepping = true;
  schedule(run);
}

// Redraws the pictures at the current exposure (while paused or done; a running
// side gets it with its next pass anyway).
function refreshPictures() {
  if (!run) return;
  run.sides.forEach(function (s) {
    if (s.busy || !s.started || !s.stats || !s.stats.passes) return;
    s.busy = true;
    s.worker.postMessage({ type: 'snapshot', linear: false, exposure: exposure() });
  });
}

function exposure() {
  var e = +$('exposure').value;
  return e > 0 ? e : 1;
}

/* ---- Views ----------------------------------------------------------------------- */

function buildSideViews(settings) {
  var host = $('sides'), tpl = $('side-template');
  host.innerHTML = '';
  host.style.setProperty('--count', settings.sides.length);
  run.views = settings.sides.map(function (s, i) {
    var node = tpl.content.firstElementChild.cloneNode(true);
    node.querySelector('.title').textContent = 'ABC'[i] + ': ' + describe(s);
    node.querySelector('.title').style.color = COLOURS[i];
    node.style.borderTopColor = COLOURS[i];
    var canvases = node.querySelectorAll('canvas');
    Array.prototype.forEach.call(canvases, function (c, k) {
      c.width = settings.width; c.height = settings.height;
      c.setAttribute('role', 'img');
      c.setAttribute('aria-label', k === 0 ? 'rendered image, setting ' + 'ABC'[i]
                                           : MAP_NAMES[k - 1] + ' map, setting ' + 'ABC'[i]);
    });
    host.appendChild(node);
    return { node: node, image: canvases[0], maps: [canvases[1], canvases[2], canvases[3]],
             scales: node.querySelectorAll('.scale'), stats: node.querySelector('.stats') };
  });
}

function putRGBA(canvas, rgba) {
  var ctx = canvas.getContext('2d');
  ctx.putImageData(new ImageData(rgba, canvas.width, canvas.height), 0, 0);
}

function drawPictures(side, p) {
  var v = side.view;
  putRGBA(v.image, p.image);
  p.maps.forEach(function (m, k) {
    var fig = v.maps[k].closest('figure');
    fig.classList.toggle('absent', !m);
    if (m) {
      putRGBA(v.maps[k], m.rgba);
      v.scales[k].textContent = k === 2 ? '(±' + fmt(m.hi) + ')' : '(top ' + fmt(m.hi) + ')';
    } else {
      v.maps[k].getContext('2d').clearRect(0, 0, v.maps[k].width, v.maps[k].height);
      v.scales[k].textContent = '(not kept by ' + side.settings.method + ')';
    }
  });
}

function fmt(x) {
  if (!(x > 0)) return '0';
  return x >= 0.01 && x < 1000 ? String(+x.toPrecision(3)) : x.toExponential(1);
}

function drawStats(side) {
  var st = side.stats;
  if (!st) return;
  var rate = st.seconds > 0 ? st.passes / st.seconds : 0;
  var err = st.error >= 0 ? (100 * st.error).toFixed(2) + ' %' + (st.noiseOnly ? ' (noise only)' : '')
                          : (st.passes < 2 ? 'after pass 2' : 'none for ' + side.settings.method);
  side.view.stats.innerHTML =
    '<span>pass <b>' + st.passes + '</b></span>' +
    '<span>photons <b>' + st.photons.toLocaleString('en-US') + '</b></span>' +
    '<span>time <b>' + st.seconds.toFixed(2) + ' s</b> (' + rate.toFixed(1) + ' passes/s)</span>' +
    '<span>est. error <b>' + err + '</b></span>';
}

/* ---- The log-log plot -------------------------------------------------------------- */

var plotPending = false;
function schedulePlot() {
  if (plotPending) return;
  plotPending = true;
  requestAnimationFrame(function () { plotPending = false; if (run) drawPlot(run); });
}

function drawPlot(r) {
  var c = $('plot'), ctx = c.getContext('2d'), W = c.width, H = c.height;
  var L = 110, R = 130, T = 20, B = 60;
  var pts = [];
  r.sides.forEach(function (s) { pts = pts.concat(s.history); });
  ctx.clearRect(0, 0, W, H);
  ctx.font = '20px sans-serif';
  ctx.fillStyle = '#111';
  if (pts.length < 2) {
    ctx.fillText('The estimated error appears from the second pass on (appm, pt, ppm).', L, H / 2);
    return;
  }
  var lx = pts.map(function (p) { return Math.log10(p[0]); }), ly = pts.map(function (p) { return Math.log10(p[1]); });
  var x0 = Math.floor(Math.min.apply(null, lx) * 2) / 2, x1 = Math.ceil(Math.max.apply(null, lx) * 2) / 2;
  var y0 = Math.floor(Math.min.apply(null, ly) * 2) / 2, y1 = Math.ceil(Math.max.apply(null, ly) * 2) / 2;
  if (x1 - x0 < 1) x1 = x0 + 1;
  if (y1 - y0 < 1) y0 = y1 - 1;
  var X = function (v) { return L + (v - x0) / (x1 - x0) * (W - L - R); };
  var Y = function (v) { return T + (y1 - v) / (y1 - y0) * (H - T - B); };
  axes(ctx, X, Y, x0, x1, y0, y1, W, H, L, R, T, B);
  guides(ctx, r, X, Y, x1);
  r.sides.forEach(function (s, i) {
    ctx.strokeStyle = COLOURS[i];
    ctx.lineWidth = 4;
    ctx.setLineDash(s.history.length && s.history[s.history.length - 1][2] ? [12, 8] : []);
    ctx.beginPath();
    s.history.forEach(function (p, k) {
      var x = X(Math.log10(p[0])), y = Y(Math.log10(p[1]));
      if (k) ctx.lineTo(x, y); else ctx.moveTo(x, y);
    });
    ctx.stroke();
    ctx.setLineDash([]);
    if (s.history.length) {
      var last = s.history[s.history.length - 1];
      ctx.fillStyle = COLOURS[i];
      ctx.fillText('ABC'[i] + ' ' + s.settings.method, X(Math.log10(last[0])) + 10,
                   Y(Math.log10(last[1])) + 6 + 22 * (i - (r.sides.length - 1) / 2));
    }
  });
}

function axes(ctx, X, Y, x0, x1, y0, y1, W, H, L, R, T, B) {
  ctx.strokeStyle = '#888';
  ctx.lineWidth = 1;
  ctx.fillStyle = '#111';
  for (var e = Math.ceil(x0); e <= x1; ++e) {
    ctx.beginPath(); ctx.moveTo(X(e), T); ctx.lineTo(X(e), H - B); ctx.stroke();
    ctx.fillText('10' + sup(e), X(e) - 20, H - B + 28);
  }
  for (e = Math.ceil(y0); e <= y1; ++e) {
    ctx.beginPath(); ctx.moveTo(L, Y(e)); ctx.lineTo(W - R, Y(e)); ctx.stroke();
    ctx.fillText('10' + sup(e), L - 62, Y(e) + 7);
  }
  ctx.fillText('photon paths traced', (L + W - R) / 2 - 90, H - 12);
  ctx.save();
  ctx.translate(24, (T + H - B) / 2 + 70);
  ctx.rotate(-Math.PI / 2);
  ctx.fillText('relative error', 0, 0);
  ctx.restore();
}

// Guides of slope -1/3 and -1/2 through the first point of the longest series.
function guides(ctx, r, X, Y, x1) {
  var best = null;
  r.sides.forEach(function (s) { if (!best || s.history.length > best.length) best = s.history; });
  if (!best || !best.length) return;
  var a = Math.log10(best[0][0]), b = Math.log10(best[0][1]);
  ctx.strokeStyle = '#777';
  ctx.fillStyle = '#444';
  ctx.lineWidth = 2;
  ctx.setLineDash([4, 6]);
  [[-1 / 3, '−1/3'], [-1 / 2, '−1/2']].forEach(function (g) {
    ctx.beginPath();
    ctx.moveTo(X(a), Y(b));
    ctx.lineTo(X(x1), Y(b + g[0] * (x1 - a)));
    ctx.stroke();
    ctx.fillText(g[1], X(x1) + 8, Y(b + g[0] * (x1 - a)) + 6);
  });
  ctx.setLineDash([]);
}

function sup(e) {
  var d = '⁰¹²³⁴⁵⁶⁷⁸⁹';
  return String(e).replace('-', '⁻').replace(/[0-9]/g, function (c) { return d[+c]; });
}

/* ---- Keyboard ------------------------------------------------------------------------ */

function onKey(e) {
  var t = e.target, typing = t && (t.tagName === 'INPUT' || t.tagName === 'SELECT' || t.tagName === 'TEXTAREA');
  if (e.ctrlKey || e.metaKey || e.altKey) return;
  if (e.key === 'Escape' && typing) { t.blur(); return; }
  if (typing) return;
  if (e.key === 'Enter' && t.tagName !== 'BUTTON') { e.preventDefault(); startRun(); }
  else if (e.key === ' ' && t.tagName !== 'BUTTON') { e.preventDefault(); togglePause(); }
  else if (e.key === 'n' || e.key === 'N') stepOnce();
  else if (e.key === '+' || e.key === '=') setExposure(exposure() * 1.25);
  else if (e.key === '-') setExposure(exposure() / 1.25);
  else if (e.key === '?') toggleHelp();
  else if (e.key >= '1' && e.key <= String(PRESETS.length)) { applyPreset(+e.key - 1); startRun(); }
}

function setExposure(e) {
  $('exposure').value = String(+e.toFixed(3));
  refreshPictures();
}

function toggleHelp() {
  var h = $('help');
  h.hidden = !h.hidden;
  $('helpbtn').setAttribute('aria-expanded', String(!h.hidden));
}

/* ---- Test hook --------------------------------------------------------------------------- */

function base64(f32) {
  var b = new Uint8Array(f32.buffer), s = '';
  for (var i = 0; i < b.length; i += 0x8000) s += String.fromCharCode.apply(null, b.subarray(i, i + 0x8000));
  return btoa(s);
}

// Distinct colours of a canvas: a map that was drawn has many, an empty one none.
function colours(canvas) {
  var d = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data, seen = new Set();
  for (var i = 0; i < d.length; i += 4) if (d[i + 3]) seen.add((d[i] << 16) | (d[i + 1] << 8) | d[i + 2]);
  return seen.size;
}

function testResult(r) {
  return { done: true, sides: r.sides.map(function (s) {
    return { method: s.settings.method, sampler: s.settings.sampler, stats: s.stats, width: r.settings.width, height: r.settings.height,
             linear: base64(s.linear), image_colours: colours(s.view.image),
             map_colours: s.view.maps.map(colours), history: s.history.length };
  }) };
}

// The state of the run, for tests/web.py: per setting its passes, seconds and busy flag.
window.appmState = function () {
  if (!run) return null;
  return { running: run.running, equal: run.settings.equal, sides: run.sides.map(function (s) {
    return { method: s.settings.method, passes: s.stats ? s.stats.passes : 0,
             seconds: s.stats ? s.stats.seconds : 0, lastPass: s.lastPass, busy: s.busy };
  }) };
};

function applyTestParams() {
  if (params.get('scene')) $('scene').value = params.get('scene');
  if (params.get('size')) { option($('size'), params.get('size'), params.get('size'), true); }
  if (params.get('seed')) $('seed').value = params.get('seed');
  if (params.get('equal')) $('equal').value = params.get('equal');
  $('scenecam').checked = params.get('camera') === 'scene';
  $('stop').value = params.get('passes') || '16';
  $('stopunit').value = 'passes';
  // methods=appm,ppm:random  (a method per setting, optionally :sampler)
  var methods = (params.get('methods') || 'appm').split(',');
  $('count').value = String(methods.length);
  var ctl = document.querySelectorAll('.sidectl');
  methods.forEach(function (m, k) {
    ctl[k].querySelector('[name=method]').value = m.split(':')[0];
    ctl[k].querySelector('[name=sampler]').value = m.split(':')[1] || 'qmc';
  });
  showSideControls();
}

/* ---- Start-up ----------------------------------------------------------------------------- */

window.addEventListener('error', function (e) { status('Error: ' + e.message); });
buildControls();
$('count').addEventListener('change', showSideControls);
$('zoom').addEventListener('change', function () { document.body.classList.toggle('zoom', $('zoom').checked); });
document.body.classList.toggle('zoom', $('zoom').checked);
$('preset').addEventListener('change', function () { if ($('preset').value !== '') applyPreset(+$('preset').value); });
$('controls').addEventListener('submit', function (e) { e.preventDefault(); startRun(); });
$('pausebtn').addEventListener('click', togglePause);
$('stepbtn').addEventListener('click', stepOnce);
$('exposure').addEventListener('change', refreshPictures);
$('helpbtn').addEventListener('click', toggleHelp);
document.addEventListener('keydown', onKey);
if (testMode) applyTestParams();
else applyPreset(0);
if (testMode || params.get('autostart') !== '0') startRun();
