/* mechdsl's interactive 3-D view (mech view, Result.view, Model.view).
 *
 * The page carries its data as JSON (script#mv-data: structure, and base64 float arrays of
 * body poses and point positions per frame) and three.js as text (script#mv-three-core,
 * #mv-three-module, #mv-orbit); the modules are imported from blob URLs, so the page needs no
 * network and works from a file:// URL and inside a notebook's iframe.  Between frames the
 * positions are interpolated linearly and the orientations by slerp, so playback is smooth
 * at any speed.  window.mechdsl_view exposes the state for tests.
 */
(function () {
  "use strict";
  var $ = function (id) { return document.getElementById(id); };
  var statusBox = $("mv-status");
  function fail(message) {
    statusBox.textContent = message;
    statusBox.style.display = "block";
  }
  function decode(text, Type) {
    var bin = atob(text), bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer);
  }

  var D = JSON.parse($("mv-data").textContent);
  var times = decode(D.times, Float64Array);
  var n = times.length, t0 = times[0], t1 = times[n - 1];
  var digits = (t1 - t0) < 1 ? 4 : 3;
  var state = { t: t0, playing: n > 1, mult: 1, last: null, k: 0, f: 0, dirty: true, rendered: 0 };
  var api = { state: state, data: D, ready: false };
  window.mechdsl_view = api;

  // ------------------------------------------------------------------ controls
  var play = $("mv-play"), range = $("mv-range"), clock = $("mv-clock"), speed = $("mv-speed"), note = $("mv-note");
  range.max = String(Math.max(n - 1, 0));
  function locate(t) {                         // frame k and fraction f with times[k] <= t <= times[k + 1]
    var lo = 0, hi = n - 1;
    if (n < 2 || t <= t0) return [0, 0];
    if (t >= t1) return [n - 2, 1];
    while (hi - lo > 1) { var mid = (lo + hi) >> 1; if (times[mid] <= t) lo = mid; else hi = mid; }
    return [lo, (t - times[lo]) / (times[lo + 1] - times[lo])];
  }
  function setPlaying(on) {
    state.playing = on && n > 1;
    state.last = null;
    play.textContent = state.playing ? "pause" : "play";
  }
  function seek(t) {
    state.t = Math.min(Math.max(t, t0), t1);
    var kf = locate(state.t);
    state.k = kf[0]; state.f = kf[1];
    range.value = String(kf[1] < 0.5 ? kf[0] : Math.min(kf[0] + 1, n - 1));
    var s = "t = " + state.t.toFixed(digits) + " s";
    var hit = D.impacts && D.impacts.some(function (ti) { return state.t >= ti && state.t - ti < 3 * (t1 - t0) / Math.max(n - 1, 1); });
    clock.textContent = s + (hit ? "  impact" : "");
    state.dirty = true;
  }
  play.addEventListener("click", function () { setPlaying(!state.playing); });
  range.addEventListener("input", function () { setPlaying(false); seek(times[parseInt(range.value, 10)]); });
  speed.addEventListener("change", function () { state.mult = parseFloat(speed.value); state.last = null; });
  document.addEventListener("keydown", function (e) {
    if (e.key === " " && e.target === document.body) { setPlaying(!state.playing); e.preventDefault(); }
  });
  setPlaying(state.playing);

  var draw = null;                             // set by the scene: draws state.k, state.f
  function tick(now) {
    if (state.playing) {
      if (state.last !== null) {
        var t = state.t + (now - state.last) / 1000 * D.speed * state.mult;
        if (t > t1) t = t0 + (t - t1) % Math.max(t1 - t0, 1e-300);    // loop
        seek(t);
      }
      state.last = now;
    }
    if (state.dirty && draw) {
      state.dirty = false;
      draw();
      state.rendered += 1;
      if (!api.ready) { api.ready = true; document.body.setAttribute("data-ready", "1"); }
    }
    requestAnimationFrame(tick);
  }

  // ------------------------------------------------------------------ bars (no bodies)
  function startBars() {
    var canvas = $("mv-canvas"), ctx = canvas.getContext("2d");
    var Q = decode(D.q, Float32Array), m = D.names.length, lo = D.range[0], hi = D.range[1];
    var pad = 0.05 * ((hi - lo) || 1); lo -= pad; hi += pad;
    var palette = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"];
    note.textContent = "no bodies to draw: the coordinates as bars";
    $("mv-reset").style.display = "none";
    draw = function () {
      var w = canvas.clientWidth, h = canvas.clientHeight, r = window.devicePixelRatio || 1;
      if (canvas.width !== Math.round(w * r)) { canvas.width = Math.round(w * r); canvas.height = Math.round(h * r); }
      ctx.setTransform(r, 0, 0, r, 0, 0);
      ctx.clearRect(0, 0, w, h);
      var left = Math.min(200, 0.3 * w), right = w - 20, top = 40, row = Math.min(40, (h - top - 20) / Math.max(m, 1));
      var X = function (v) { return left + (v - lo) / (hi - lo) * (right - left); };
      ctx.font = "13px sans-serif"; ctx.textBaseline = "middle";
      for (var i = 0; i < m; i++) {
        var a = Q[state.k * m + i], b = Q[Math.min(state.k + 1, n - 1) * m + i], v = a + (b - a) * state.f;
        var y = top + i * row;
        ctx.fillStyle = palette[i % palette.length];
        ctx.fillRect(Math.min(X(0), X(v)), y + 0.15 * row, Math.abs(X(v) - X(0)), 0.7 * row);
        ctx.fillStyle = "#222";
        ctx.fillText(D.names[i] + (D.units[i] ? " [" + D.units[i] + "]" : ""), 8, y + row / 2);
      }
      ctx.strokeStyle = "#222"; ctx.beginPath(); ctx.moveTo(X(0), top - 5); ctx.lineTo(X(0), top + m * row + 5); ctx.stroke();
    };
    new ResizeObserver(function () { state.dirty = true; }).observe(canvas);
  }

  // ------------------------------------------------------------------ 3-D
  async function start3d() {
    var url = function (src) { return URL.createObjectURL(new Blob([src], { type: "text/javascript" })); };
    var core = url($("mv-three-core").textContent);
    var mod = url($("mv-three-module").textContent.split('"./three.core.min.js"').join(JSON.stringify(core)));
    var orbit = url($("mv-orbit").textContent.split("from 'three'").join("from " + JSON.stringify(mod)));
    var THREE = await import(mod);
    var OrbitControls = (await import(orbit)).OrbitControls;
    var canvas = $("mv-canvas"), renderer;
    try {
      renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: true, preserveDrawingBuffer: true });
    } catch (e) {
      fail("This view needs WebGL, which this browser does not offer here (" + e.message + ").");
      return;
    }
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    var S = D.scale, V3 = THREE.Vector3;
    var up = new V3().fromArray(D.up), center = new V3().fromArray(D.center);
    var scene = new THREE.Scene();
    scene.background = new THREE.Color(0xffffff);
    var camera = new THREE.PerspectiveCamera(35, 1, S * 0.005, S * 200);
    camera.up.copy(up);
    var toward = new V3().fromArray(D.toward_viewer);
    var right = new V3().crossVectors(up, toward).normalize(), sup = new V3().crossVectors(toward, right);
    var home = new V3(), touched = false;
    function frame(aspect) {                   // the distance that shows the box of every frame, with a margin
      var tan = Math.tan(THREE.MathUtils.degToRad(17.5)), h = 0, w = 0, near = 0, e = D.extent;
      for (var i = 0; i < 8; i++) {
        var c = new V3((i & 1 ? 0.5 : -0.5) * e[0], (i & 2 ? 0.5 : -0.5) * e[1], (i & 4 ? 0.5 : -0.5) * e[2]);
        h = Math.max(h, Math.abs(c.dot(sup))); w = Math.max(w, Math.abs(c.dot(right))); near = Math.max(near, c.dot(toward));
      }
      var dist = 1.12 * Math.max(h / tan, w / (tan * aspect), 0.1 * S) + near;
      home.copy(center).addScaledVector(toward, dist);
    }
    frame(1.4);
    camera.position.copy(home);
    camera.lookAt(center);
    var controls = new OrbitControls(camera, canvas);
    controls.target.copy(center);
    controls.update();
    controls.addEventListener("change", function () { state.dirty = true; });
    controls.addEventListener("start", function () { touched = true; });
    $("mv-reset").addEventListener("click", function () {
      camera.position.copy(home); controls.target.copy(center); controls.update(); touched = false; state.dirty = true;
    });
    var hemi = new THREE.HemisphereLight(0xffffff, 0x888888, 2.2);
    hemi.position.copy(up);
    scene.add(hemi);
    var sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(0.4, 0.8, 1.0);
    camera.add(sun);
    scene.add(camera);

    var Y = new V3(0, 1, 0), Z = new V3(0, 0, 1);
    function material(colour, opacity) {
      var m = new THREE.MeshStandardMaterial({ color: colour, roughness: 0.55, metalness: 0.05 });
      if (opacity < 1) { m.transparent = true; m.opacity = opacity; m.depthWrite = false; m.side = THREE.DoubleSide; }
      return m;
    }
    function solid(s, colour) {
      var g, z = s.size;
      if (s.kind === "rod") g = new THREE.CylinderGeometry(Math.min(0.012 * S, z[0] / 6), Math.min(0.012 * S, z[0] / 6), z[0], 20).rotateX(Math.PI / 2);
      else if (s.kind === "disk") g = new THREE.CylinderGeometry(z[0], z[0], Math.max(0.08 * z[0], 0.004 * S), 48).rotateX(Math.PI / 2);
      else if (s.kind === "cylinder") g = new THREE.CylinderGeometry(z[0], z[0], z[1], 48).rotateX(Math.PI / 2);
      else if (s.kind === "box") g = new THREE.BoxGeometry(z[0], z[1], z[2]);
      else g = new THREE.SphereGeometry(1, 48, 24);
      var mesh = new THREE.Mesh(g, material(colour, s.translucent ? 0.5 : 1));
      if (s.kind === "sphere") mesh.scale.setScalar(z[0]);
      if (s.kind === "ellipsoid") {              // it stands for the inertia: translucent, its principal axes drawn
        mesh.scale.set(z[0], z[1], z[2]);
        var axes = new THREE.LineSegments(new THREE.BufferGeometry().setFromPoints([
          new V3(-1, 0, 0), new V3(1, 0, 0), new V3(0, -1, 0), new V3(0, 1, 0), new V3(0, 0, -1), new V3(0, 0, 1)]),
          new THREE.LineBasicMaterial({ color: 0x333333 }));
        mesh.add(axes);
      }
      mesh.position.fromArray(s.center);
      mesh.quaternion.fromArray(s.quat);
      return mesh;
    }
    var grey = material(0x9a9a9a, 1);
    var groups = D.bodies.map(function (b) {
      var g = new THREE.Group();
      b.solids.forEach(function (s) { g.add(solid(s, b.colour)); });
      b.hoops.forEach(function (h) {
        var ring = new THREE.Mesh(new THREE.TorusGeometry(h.radius, 0.004 * S, 8, 120), grey);
        ring.position.fromArray(h.center);
        ring.quaternion.setFromUnitVectors(Z, new V3().fromArray(h.normal).normalize());
        g.add(ring);
      });
      scene.add(g);
      return g;
    });
    var poses = decode(D.poses, Float32Array), B = D.bodies.length;
    var P = D.n_points ? decode(D.points, Float32Array) : new Float32Array(0), K = D.n_points;
    var qa = new THREE.Quaternion(), qb = new THREE.Quaternion();
    function point(c, out) {                   // interpolated world position of page column c
      var a = (state.k * K + c) * 3, b = (Math.min(state.k + 1, n - 1) * K + c) * 3, f = state.f;
      return out.set(P[a] + (P[b] - P[a]) * f, P[a + 1] + (P[b + 1] - P[a + 1]) * f, P[a + 2] + (P[b + 2] - P[a + 2]) * f);
    }
    function segment(mesh, a, b) {              // a unit cylinder along y stretched from a to b
      var d = new V3().subVectors(b, a), len = d.length();
      mesh.position.copy(a).addScaledVector(d, 0.5);
      if (len > 0) mesh.quaternion.setFromUnitVectors(Y, d.divideScalar(len));
      mesh.scale.set(1, Math.max(len, 1e-9), 1);
    }
    function rodMesh(radius, mat) { return new THREE.Mesh(new THREE.CylinderGeometry(radius, radius, 1, 12), mat); }
    var updaters = [];
    var A = new V3(), Bv = new V3();
    D.items.forEach(function (it) {
      var c = it.cols;
      if (it.kind === "point" || it.kind === "sphere") {
        var ball = new THREE.Mesh(new THREE.SphereGeometry(it.kind === "sphere" ? it.radius : 0.025 * S, 32, 16), material(it.colour, 1));
        scene.add(ball);
        updaters.push(function () { point(c[0], ball.position); });
      } else if (it.kind === "link" || it.kind === "arm") {
        var rod = rodMesh(it.kind === "link" ? 0.006 * S : 0.003 * S, it.kind === "link" ? material(it.colour, 1) : grey);
        scene.add(rod);
        updaters.push(function () { segment(rod, point(c[0], A), point(c[1], Bv)); });
      } else if (it.kind === "spring") {
        var m = 160, coil = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0x555555 }));
        coil.geometry.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * (m + 1)), 3));
        coil.frustumCulled = false;
        scene.add(coil);
        updaters.push(function () {
          point(c[0], A); point(c[1], Bv);
          var d = new V3().subVectors(Bv, A), u = new V3(), w = new V3();
          var axis = d.clone().normalize();
          u.crossVectors(axis, Math.abs(axis.z) < 0.9 ? Z : Y).normalize();
          w.crossVectors(axis, u);
          var arr = coil.geometry.attributes.position.array, r = 0.02 * S;
          for (var i = 0; i <= m; i++) {
            var s = i / m, ends = s < 0.1 || s > 0.9, phase = 2 * Math.PI * 10 * (s - 0.1) / 0.8;
            var k = ends ? 0 : r;
            arr[3 * i] = A.x + d.x * s + k * (Math.cos(phase) * u.x + Math.sin(phase) * w.x);
            arr[3 * i + 1] = A.y + d.y * s + k * (Math.cos(phase) * u.y + Math.sin(phase) * w.y);
            arr[3 * i + 2] = A.z + d.z * s + k * (Math.cos(phase) * u.z + Math.sin(phase) * w.z);
          }
          coil.geometry.attributes.position.needsUpdate = true;
        });
      } else if (it.kind === "damper") {
        var cup = rodMesh(0.015 * S, material(0x777777, 1)), piston = rodMesh(0.004 * S, grey);
        scene.add(cup); scene.add(piston);
        updaters.push(function () {
          point(c[0], A); point(c[1], Bv);
          segment(cup, A, A.clone().lerp(Bv, 0.55));
          segment(piston, A.clone().lerp(Bv, 0.4), Bv);
        });
      } else if (it.kind === "pin") {
        var pin = new THREE.Mesh(new THREE.SphereGeometry(0.012 * S, 16, 8), material(0xffffff, 1));
        scene.add(pin);
        updaters.push(function () { point(c[0], pin.position); });
        if (it.ground) {
          var cone = new THREE.Mesh(new THREE.ConeGeometry(0.03 * S, 0.05 * S, 24), material(0xbbbbbb, 1));
          state.k = 0; state.f = 0;
          point(c[0], cone.position).addScaledVector(up, -0.037 * S);
          cone.quaternion.setFromUnitVectors(Y, up);
          scene.add(cone);
        }
      } else if (it.kind === "rail") {
        var lo = new V3(Infinity, Infinity, Infinity), hi = new V3(-Infinity, -Infinity, -Infinity), q = new V3();
        for (var k = 0; k < n; k++) { state.k = k; state.f = 0; point(c[0], q); lo.min(q); hi.max(q); }
        var ext = new V3().subVectors(hi, lo);
        if (ext.length() > 0) {
          var rail = rodMesh(0.004 * S, material(0xaaaaaa, 1));
          segment(rail, lo.clone().addScaledVector(ext, -0.1), hi.clone().addScaledVector(ext, 0.1));
          scene.add(rail);
        }
      } else if (it.kind === "ring") {
        var shell = new THREE.Mesh(new THREE.SphereGeometry(it.radius, 48, 24), material(0xaaaaaa, 0.25));
        scene.add(shell);
        updaters.push(function () { point(c[0], shell.position); });
      } else if (it.kind === "trace") {
        var path = new Float32Array(3 * n), p = new V3();
        for (var j = 0; j < n; j++) { state.k = j; state.f = 0; point(c[0], p); path[3 * j] = p.x; path[3 * j + 1] = p.y; path[3 * j + 2] = p.z; }
        var line = new THREE.Line(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0xd62728 }));
        line.geometry.setAttribute("position", new THREE.BufferAttribute(path, 3));
        line.frustumCulled = false;
        scene.add(line);
        updaters.push(function () { line.geometry.setDrawRange(0, state.k + 1); });
      }
    });
    D.planes.forEach(function (pl) {
      var normal = new V3().fromArray(pl.normal), base = new V3().fromArray(pl.base);
      var mesh = new THREE.Mesh(new THREE.PlaneGeometry(2 * S, 2 * S), material(0xdddddd, 0.6));
      mesh.quaternion.setFromUnitVectors(Z, normal);
      mesh.position.copy(center).addScaledVector(normal, -new V3().subVectors(center, base).dot(normal));
      scene.add(mesh);
    });
    if (!D.planes.length) {                      // a faint floor under the mechanism, across the up direction
      var e10 = Math.pow(10, Math.floor(Math.log10(S / 5))), cell = [1, 2, 5, 10].map(function (m) { return m * e10; })
        .filter(function (c) { return c >= S / 5 - 1e-12; })[0];
      var cells = 2 * Math.ceil(0.75 * S / cell);     // the floor is about 1.5 times the scene: small
      var grid = new THREE.GridHelper(cells * cell, cells, 0xc8c8c8, 0xe4e4e4);   // (no lines behind the camera)
      var ext3 = new V3().fromArray(D.extent);
      var low = center.dot(up) - 0.5 * (Math.abs(ext3.x * up.x) + Math.abs(ext3.y * up.y) + Math.abs(ext3.z * up.z));
      grid.quaternion.setFromUnitVectors(Y, up);
      grid.position.copy(center).divideScalar(cell).round().multiplyScalar(cell);
      grid.position.addScaledVector(up, low - grid.position.dot(up));
      scene.add(grid);
    }
    scene.add(new THREE.AxesHelper(0.15 * S));
    seek(state.t);

    function resize() {
      var w = canvas.clientWidth, h = canvas.clientHeight;
      if (!w || !h) return;
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      camera.updateProjectionMatrix();
      frame(w / h);
      if (!touched) { camera.position.copy(home); controls.target.copy(center); controls.update(); }
      state.dirty = true;
    }
    new ResizeObserver(resize).observe(canvas);
    resize();
    draw = function () {
      var k = state.k, k2 = Math.min(k + 1, n - 1), f = state.f;
      for (var b = 0; b < B; b++) {
        var a = (k * B + b) * 7, e = (k2 * B + b) * 7, g = groups[b];
        g.position.set(poses[a] + (poses[e] - poses[a]) * f, poses[a + 1] + (poses[e + 1] - poses[a + 1]) * f,
                       poses[a + 2] + (poses[e + 2] - poses[a + 2]) * f);
        qa.set(poses[a + 3], poses[a + 4], poses[a + 5], poses[a + 6]);
        qb.set(poses[e + 3], poses[e + 4], poses[e + 5], poses[e + 6]);
        g.quaternion.slerpQuaternions(qa, qb, f);
      }
      updaters.forEach(function (u) { u(); });
      renderer.render(scene, camera);
    };
    api.camera = camera;
    api.scene = scene;
    api.controls = controls;
  }

  seek(t0);
  requestAnimationFrame(tick);
  if (D.mode === "bars") startBars();
  else start3d().catch(function (e) { fail("The 3-D view could not start: " + e); });
})();
