/* worker.js - one appm renderer in a Web Worker, so that passes never block the page.
 *
 * Messages in (from the page):
 *   {type: 'load', obj, mtl, name}       the scene, as OBJ and MTL text (camera framed)
 *   {type: 'load', scene, sceneName, obj, objName, mtl, mtlName}
 *                                        the same with the .scene naming them (its camera)
 *   {type: 'start', opts}                a new renderer (opts: method, sampler, width,
 *                                        height, photons, radiusFactor, alpha, seed)
 *   {type: 'pass', pictures, exposure}   one pass; pictures: send the image and maps too
 *   {type: 'snapshot', linear, exposure} the image and maps now (and the float image)
 * Messages out:
 *   {type: 'ready'}, {type: 'started', stats}, {type: 'passed', stats, pictures?},
 *   {type: 'snapshot', stats, pictures, linear?}, {type: 'error', message}
 * pictures = {image: RGBA bytes, maps: [{rgba, hi} or null] for radius, variance,
 * Laplacian}; every buffer is transferred, not copied.
 */
'use strict';
importScripts('appm-wasm.js');

var appm = null, pending = [];

function fail(e) {
  self.postMessage({ type: 'error', message: String(e && e.message ? e.message : e) });
}

// The image and the three maps of the adaptive method (radius, variance, Laplacian).
function pictures(exposure, transfer) {
  var p = { image: appm.rgba(exposure), maps: [] };
  transfer.push(p.image.buffer);
  for (var k = 0; k < 3; ++k) {
    var m = appm.aux(k);
    p.maps.push(m);
    if (m) transfer.push(m.rgba.buffer);
  }
  return p;
}

// radiusFactor scales the automatic radius, which the library picks in the first
// pass from the eye pass's footprints: a one-pass probe finds it, as bench/teach.sh
// does with `appm render --passes 1`.
function start(o) {
  var f = o.radiusFactor || 1, radius = 0;
  if (f !== 1) {
    appm.start({ method: 'ppm', sampler: o.sampler, width: o.width, height: o.height,
                 photons: o.photons, seed: o.seed });
    appm.pass();
    radius = appm.stats().radius * f;
  }
  appm.start({ method: o.method, sampler: o.sampler, width: o.width, height: o.height,
               photons: o.photons, radius: radius, alpha: o.alpha, seed: o.seed });
}

function handle(msg) {
  var t = [];
  switch (msg.type) {
  case 'load':
    if (msg.scene) appm.loadScene(msg.scene, msg.sceneName, msg.obj, msg.objName, msg.mtl, msg.mtlName);
    else appm.load(msg.obj, msg.mtl, msg.name);
    self.postMessage({ type: 'loaded' });
    break;
  case 'start':
    start(msg.opts);
    self.postMessage({ type: 'started', stats: appm.stats() });
    break;
  case 'pass':
    appm.pass();
    var out = { type: 'passed', stats: appm.stats() };
    if (msg.pictures) out.pictures = pictures(msg.exposure, t);
    self.postMessage(out, t);
    break;
  case 'snapshot':
    var s = { type: 'snapshot', stats: appm.stats(), pictures: pictures(msg.exposure, t) };
    if (msg.linear) { s.linear = appm.linear(); t.push(s.linear.buffer); }
    self.postMessage(s, t);
    break;
  default:
    throw new Error('worker: unknown message ' + msg.type);
  }
}

self.onmessage = function (e) {
  if (!appm) { pending.push(e.data); return; }
  try { handle(e.data); } catch (err) { fail(err); }
};

fetch('appm.wasm').then(function (r) {
  if (!r.ok) throw new Error('appm.wasm: HTTP ' + r.status + ' (run make web)');
  return r.arrayBuffer();
}).then(AppmWasm.create).then(function (a) {
  appm = a;
  self.postMessage({ type: 'ready' });
  while (pending.length) {
    try { handle(pending.shift()); } catch (err) { fail(err); }
  }
}).catch(fail);
