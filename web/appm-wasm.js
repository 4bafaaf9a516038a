/* appm-wasm.js - appm.wasm (appm.c + shim.c) behind a small JavaScript object.
 *
 * Used by worker.js (one instance per Web Worker).  Plain script, no modules, so
 * that a classic worker can importScripts() it.  The library does no file I/O
 * here: the scene comes in as OBJ and MTL text, with or without a .scene text.  The few WASI functions that the
 * C library links still need an import each; all but the clock answer ENOSYS.
 */
'use strict';

var AppmWasm = (function () {
  var ENOSYS = 52, EBADF = 8;

  function wasiImports(self) {
    function mem() { return new DataView(self.memory.buffer); }
    var stub = function () { return ENOSYS; };
    return {
      clock_time_get: function (id, precision, out) {
        // Nanoseconds as a u64; performance.now() is monotonic, in milliseconds.
        var ns = BigInt(Math.round(performance.now() * 1e6));
        mem().setBigUint64(out, ns, true);
        return 0;
      },
      fd_prestat_get: function () { return EBADF; }, // no preopened folders
      fd_prestat_dir_name: function () { return EBADF; },
      fd_close: stub, fd_fdstat_get: stub, fd_fdstat_set_flags: stub, fd_read: stub,
      fd_seek: stub, fd_write: stub, path_open: stub,
      proc_exit: function (code) { throw new Error('appm.wasm called exit(' + code + ')'); },
    };
  }

  function AppmWasm() {}

  // bytes: the contents of appm.wasm (an ArrayBuffer or typed array).
  AppmWasm.create = function (bytes) {
    var self = new AppmWasm();
    var imports = { wasi_snapshot_preview1: wasiImports(self) };
    return WebAssembly.instantiate(bytes, imports).then(function (res) {
      var inst = res.instance || res;
      self.x = inst.exports;
      self.memory = inst.exports.memory;
      // A WASI reactor: _initialize runs the C library's start-up once.
      if (self.x._initialize) self.x._initialize();
      self.methods = {}; // the library's names: appm, ppm, sppm, pt, appm-paper
      for (var m = 0; m < self.x.web_method_count(); ++m) self.methods[self.cstring(self.x.web_method_name(m))] = m;
      return self;
    });
  };

  AppmWasm.prototype.cstring = function (ptr) {
    var b = new Uint8Array(this.memory.buffer), end = ptr;
    while (b[end]) end++;
    return new TextDecoder().decode(b.subarray(ptr, end));
  };

  AppmWasm.prototype.error = function () { return this.cstring(this.x.web_error()); };

  // Copies a JavaScript string into the instance's memory; returns [ptr, len].
  AppmWasm.prototype.put = function (text) {
    var bytes = new TextEncoder().encode(text || '');
    var p = this.x.web_alloc(bytes.length + 1);
    if (!p) throw new Error('appm.wasm: out of memory for ' + bytes.length + ' bytes');
    var m = new Uint8Array(this.memory.buffer, p, bytes.length + 1);
    m.set(bytes);
    m[bytes.length] = 0;
    return [p, bytes.length];
  };

  // Loads a scene from OBJ and MTL text; throws with the library's file:line message.
  AppmWasm.prototype.load = function (obj, mtl, name) {
    var o = this.put(obj), m = this.put(mtl), n = this.put(name || 'scene.obj');
    var s = this.x.web_load(o[0], o[1], m[0], m[1], n[0]);
    this.x.web_free(o[0]); this.x.web_free(m[0]); this.x.web_free(n[0]);
    if (s !== 0) throw new Error(this.error());
  };

  // Loads a .scene text with the OBJ and MTL it names (objName, mtlName: the names its mesh
  // and mtllib lines give), so that the .scene's camera and lights are used.
  AppmWasm.prototype.loadScene = function (scene, name, obj, objName, mtl, mtlName) {
    var t = [this.put(scene), this.put(name), this.put(obj), this.put(objName), this.put(mtl), this.put(mtlName)];
    var s = this.x.web_load_scene(t[0][0], t[0][1], t[1][0], t[2][0], t[2][1], t[3][0], t[4][0], t[4][1], t[5][0]);
    for (var k = 0; k < t.length; ++k) this.x.web_free(t[k][0]);
    if (s !== 0) throw new Error(this.error());
  };

  var SAMPLERS = { qmc: 0, random: 1 }; // appm_sampler

  // opts: method (name), sampler ('qmc' or 'random'), width, height, photons, radius,
  // alpha, seed (0: defaults).
  AppmWasm.prototype.start = function (o) {
    var m = this.methods[o.method];
    if (m === undefined) throw new Error('unknown method ' + o.method + ' (the library has ' +
                                         Object.keys(this.methods).join(', ') + ')');
    var smp = SAMPLERS[o.sampler || 'qmc'];
    if (smp === undefined) throw new Error('unknown sampler ' + o.sampler);
    this.width = o.width; this.height = o.height;
    var s = this.x.web_create(m, smp, o.width, o.height, o.photons || 0, o.radius || 0,
                              o.alpha || 0, o.seed || 0);
    if (s !== 0) throw new Error(this.error());
  };

  AppmWasm.prototype.pass = function () {
    var s = this.x.web_pass();
    if (s !== 0) throw new Error('pass failed: ' + this.error());
  };

  AppmWasm.prototype.stats = function () {
    var f = this.x.web_stat;
    return { passes: f(0), photons: f(1), seconds: f(2), error: f(3), radius: f(4),
             bytes: f(5), stored: f(6), eyePaths: f(7), noiseOnly: f(8) === 1 };
  };

  // The image as 8-bit sRGB RGBA (a copy), or null before the renderer exists.
  AppmWasm.prototype.rgba = function (exposure) {
    var p = this.x.web_image_rgba(exposure || 1);
    if (!p) return null;
    return new Uint8ClampedArray(this.memory.buffer.slice(p, p + 4 * this.width * this.height));
  };

  // The linear float RGB image (a copy): what `appm render -o x.pfm` writes.
  AppmWasm.prototype.linear = function () {
    var p = this.x.web_image();
    if (!p) return null;
    return new Float32Array(this.memory.buffer.slice(p, p + 12 * this.width * this.height));
  };

  // A diagnostic map (0 radius, 1 variance, 2 Laplacian, 3 error) as false-colour
  // RGBA plus the top of its scale, or null when the method keeps no such map.
  AppmWasm.prototype.aux = function (which) {
    var p = this.x.web_aux_rgba(which);
    if (!p) return null;
    return { rgba: new Uint8ClampedArray(this.memory.buffer.slice(p, p + 4 * this.width * this.height)),
             hi: this.x.web_aux_hi() };
  };

  return AppmWasm;
})();

if (typeof module !== 'undefined') module.exports = AppmWasm;
