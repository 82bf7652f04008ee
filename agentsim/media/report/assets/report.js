/* agentsim run report: the page of agentsim.media.report.

   It reads window.REPORT_DATA (timeline, table, skeleton) and window.REPORT_POSES (quantized joint
   positions), both set by classic scripts loaded before this one, and window.THREE (the vendored
   three.js). One clock drives everything: the <audio> element while the run's sound plays, else a clock
   of the page (a run without sound, or the part of the run after its sound ended). Every change of time
   moves the skeleton, the timeline's cursor and the table's current row.

   window.report is the page's API for tests: ready, duration(), seek(t), time(), joint(name),
   cursor() (the cursor's x in CSS px on the timeline canvas), cursorTime(), play(), pause(), errors.

   With window.REPORT_LIVE set instead of REPORT_DATA (the page agentsim serve serves at /), the same 3D
   view plays a live run: see live() at the end of this file. */
(function () {
  "use strict";

  var D = window.REPORT_DATA;
  var P = window.REPORT_POSES || null;
  var LIVE = window.REPORT_LIVE || null;
  var errors = window.reportErrors || [];
  var api = { ready: false, errors: errors };
  window.report = api;
  if (!D && !LIVE) { errors.push("REPORT_DATA did not load"); return; }

  var $ = function (id) { return document.getElementById(id); };
  var clamp = function (x, lo, hi) { return x < lo ? lo : (x > hi ? hi : x); };
  var fmt = function (x, d) { return x === null || x === undefined ? "" : x.toFixed(d === undefined ? 3 : d); };
  var COLOURS = { preparation: "#9ecae1", "pre-stroke hold": "#c6dbef", stroke: "#2171b5",
    "post-stroke hold": "#c6dbef", retraction: "#9ecae1", other: "#bdbdbd", speech: "#a1d99b", speech2: "#74c476" };
  var PHASES = { start: "preparation", ready: "pre-stroke hold", strokeStart: "stroke", stroke: "stroke",
    attackPeak: "stroke", strokeEnd: "post-stroke hold", relax: "retraction" };
  var FEED_COLOURS = { syncPointProgress: "#718096", blockProgress: "#2b6cb0", warningFeedback: "#e53e3e",
    predictionFeedback: "#38a169" };
  var LABEL = 190, RIGHT = 12, RULER = 18, FEED = 12, SPEECH_H = 16, WORDS_H = 44, ROW_H = 15, TL_H = 330, OV_H = 40;
  var three = null;
  if (LIVE) {
    try { live(LIVE); } catch (e) { errors.push("report.js: " + e.message); throw e; }
    return;
  }
  var duration = Math.max(D.duration || 0, 0.001);

  /* ------------------------------------------------------------------------------------- the clock */
  var audio = $("audio");
  var clock = { playing: false, base: 0, started: 0 };
  var mode = audio ? "audio" : "clock";

  function audioDuration() {
    if (!audio) return 0;
    var d = audio.duration;
    return isFinite(d) && d > 0 ? d : (D.audio ? D.audio.duration : 0);
  }
  function clockTime() {
    if (!clock.playing) return clock.base;
    var t = clock.base + (performance.now() - clock.started) / 1000;
    if (t >= duration) { clock.playing = false; clock.base = duration; t = duration; buttons(); }
    return t;
  }
  function now() { return mode === "audio" ? audio.currentTime : clockTime(); }
  function playing() { return mode === "audio" ? !audio.paused && !audio.ended : clock.playing; }
  function startClock(t) { mode = "clock"; clock.base = t; clock.started = performance.now(); clock.playing = true; }
  function seek(t) {
    t = clamp(+t || 0, 0, duration);
    var was = playing();
    if (audio && t < audioDuration() - 1e-4) {
      clock.playing = false;
      mode = "audio";
      audio.currentTime = t;
    } else {
      if (audio && !audio.paused) audio.pause();
      mode = "clock";
      clock.base = t;
      clock.started = performance.now();
      clock.playing = was && t < duration;
    }
    draw(true);
    return now();
  }
  function play() {
    var t = now();
    if (t >= duration - 1e-3) t = seek(0);
    if (audio && t < audioDuration() - 1e-3) {
      mode = "audio";
      clock.playing = false;
      var p = audio.play();
      if (p && p.catch) p.catch(function (e) {
        // no audio device, or playback refused: go on with the page's clock, silently
        note("the audio did not play (" + e.name + "); playing without sound");
        startClock(audio.currentTime);
        buttons();
      });
    } else {
      startClock(t);
    }
    buttons();
  }
  function pause() {
    if (audio && !audio.paused) audio.pause();
    if (clock.playing) { clock.base = clockTime(); clock.playing = false; }
    buttons();
    draw(true);
  }
  function buttons() { $("play").innerHTML = playing() ? "&#10074;&#10074; pause" : "&#9654; play"; }
  function note(text) {
    var el = $("now");
    var p = document.createElement("p");
    p.className = "note";
    p.textContent = text;
    el.parentNode.insertBefore(p, el);
  }
  if (audio) {
    audio.addEventListener("play", function () { mode = "audio"; clock.playing = false; buttons(); });
    audio.addEventListener("pause", buttons);
    audio.addEventListener("seeking", function () { if (mode === "audio") draw(true); });
    audio.addEventListener("timeupdate", function () { if (mode === "audio") draw(false); });
    audio.addEventListener("ended", function () {
      // the run may go on after its sound: the page's clock takes over until the end
      if (duration > audioDuration() + 0.01) startClock(audioDuration());
      buttons();
    });
  }
  $("play").addEventListener("click", function () { if (playing()) pause(); else play(); });
  var scrub = $("scrub");
  scrub.max = String(duration);
  scrub.addEventListener("input", function () { seek(parseFloat(scrub.value)); });
  document.addEventListener("keydown", function (e) {
    var tag = (e.target && e.target.tagName) || "";
    if (tag === "INPUT" || tag === "AUDIO" || tag === "BUTTON") return;
    if (e.key === " ") { e.preventDefault(); if (playing()) pause(); else play(); }
    else if (e.key === "ArrowLeft") seek(now() - (e.shiftKey ? 0.1 : 1));
    else if (e.key === "ArrowRight") seek(now() + (e.shiftKey ? 0.1 : 1));
  });

  /* ------------------------------------------------------------------------------------- the poses */
  var M = D.motion, NP = 0, times = null, xyz = null, pts = null;
  function decode(b64, Type) {
    var bin = atob(b64), n = bin.length, bytes = new Uint8Array(n);
    for (var i = 0; i < n; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer, 0, n / Type.BYTES_PER_ELEMENT);  // little-endian, as written
  }
  if (M && P) {
    NP = P.points;
    var idx = decode(P.frames, Uint32Array);
    times = new Float64Array(idx.length);
    for (var k = 0; k < idx.length; k++) times[k] = P.t0 + idx[k] / P.fps;
    xyz = decode(P.xyz, Int16Array);
    pts = new Float64Array(NP * 3);
  }
  function poseAt(t) {
    var n = times.length, i = 0, j = 0, w = 0;
    if (t <= times[0]) { i = j = 0; }
    else if (t >= times[n - 1]) { i = j = n - 1; }
    else {
      var lo = 0, hi = n - 1;
      while (hi - lo > 1) { var mid = (lo + hi) >> 1; if (times[mid] <= t) lo = mid; else hi = mid; }
      i = lo; j = hi; w = (t - times[lo]) / (times[hi] - times[lo]);
    }
    var a = i * NP * 3, b = j * NP * 3, s = P.scale, o = P.origin;
    for (var q = 0; q < NP * 3; q++) pts[q] = o[q % 3] + s * (xyz[a + q] * (1 - w) + xyz[b + q] * w);
  }

  /* ------------------------------------------------------------------------------------- the 3D view */
  /* The skeleton M ({points, parents, face, ends}: the joints' names, each one's parent, the face's and the
     end sites' indices) in a three.js scene, standing in the positions pts (x, y, z of every point, m). */
  function buildScene(M, pts) {
    var T = window.THREE, view = $("view"), NP = M.points.length;
    if (!T) { errors.push("three.js did not load"); return null; }
    var s = { T: T, scene: new T.Scene(), spheres: [], bones: [], dirty: true, renderer: null };
    s.scene.background = new T.Color(0xf4f5f7);
    s.scene.add(new T.HemisphereLight(0xffffff, 0x8090a0, 2.2));
    var sun = new T.DirectionalLight(0xffffff, 1.6);
    sun.position.set(2, 4, 3);
    s.scene.add(sun);
    var floor = Infinity;
    for (var k = 0; k < NP; k++) floor = Math.min(floor, pts[k * 3 + 1]);
    var root = [pts[0], pts[1], pts[2]];
    var grid = new T.GridHelper(6, 30, 0x99a3ad, 0xcfd5db);
    grid.position.set(root[0], floor - 0.005, root[2]);
    s.scene.add(grid);
    var face = new Set(M.face), ends = new Set(M.ends);
    var sphereGeo = new T.SphereGeometry(1, 14, 10);
    var jointMat = new T.MeshStandardMaterial({ color: 0x2b6cb0, roughness: 0.5 });
    var tipMat = new T.MeshStandardMaterial({ color: 0x718096, roughness: 0.6 });
    for (var i = 0; i < NP; i++) {
      var r = ends.has(i) ? 0.008 : (face.has(i) ? 0.005 : (i === 0 ? 0.028 : 0.018));
      var m = new T.Mesh(sphereGeo, ends.has(i) ? tipMat : jointMat);
      m.scale.setScalar(r);
      m.name = M.points[i];
      s.scene.add(m);
      s.spheres.push(m);
    }
    var boneGeo = new T.CylinderGeometry(1, 1, 1, 10, 1);
    var boneMat = new T.MeshStandardMaterial({ color: 0xa0aec0, roughness: 0.7 });
    for (var c = 0; c < NP; c++) {
      var p = M.parents[c];
      if (p < 0) continue;
      var bm = new T.Mesh(boneGeo, boneMat);
      s.bones.push({ mesh: bm, a: p, b: c, r: face.has(c) || face.has(p) ? 0.002 : 0.009 });
      s.scene.add(bm);
    }
    var head = M.points.indexOf("skullbase"), top = M.points.indexOf("skullbase.end");
    if (head >= 0 && top >= 0) {
      s.head = new T.Mesh(new T.SphereGeometry(0.1, 24, 16),
        new T.MeshStandardMaterial({ color: 0xe2c4a8, transparent: true, opacity: 0.35, roughness: 0.8 }));
      s.headPoints = [head, top];
      s.scene.add(s.head);
    }
    var box = view.getBoundingClientRect();
    s.camera = new T.PerspectiveCamera(32, Math.max(box.width, 1) / Math.max(box.height, 1), 0.05, 100);
    s.target = new T.Vector3(root[0], root[1] + 0.1, root[2]);
    s.camera.position.set(root[0] + 0.9, root[1] + 0.4, root[2] + 3.0);
    s.follow = root;
    try {
      s.renderer = new T.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
      s.renderer.setPixelRatio(window.devicePixelRatio || 1);
      s.renderer.setSize(Math.max(box.width, 1), Math.max(box.height, 1));
      view.appendChild(s.renderer.domElement);
      s.controls = new T.OrbitControls(s.camera, s.renderer.domElement);
      s.controls.target.copy(s.target);
      s.controls.update();
      s.controls.addEventListener("change", function () { s.dirty = true; });
    } catch (e) {
      s.renderer = null;
      var msg = document.createElement("p");
      msg.className = "missing";
      msg.textContent = "the 3D view needs WebGL (" + e.message + ")";
      view.appendChild(msg);
      s.camera.lookAt(s.target);
    }
    if (window.ResizeObserver) {
      new ResizeObserver(function () {
        var b = view.getBoundingClientRect();
        if (!s.renderer || b.width < 2 || b.height < 2) return;
        s.renderer.setSize(b.width, b.height);
        s.camera.aspect = b.width / b.height;
        s.camera.updateProjectionMatrix();
        s.dirty = true;
      }).observe(view);
    }
    s.up = new T.Vector3(0, 1, 0);
    s.va = new T.Vector3();
    s.vb = new T.Vector3();
    s.dir = new T.Vector3();
    if (window.REPORT_STAGE && D && D.environment) window.REPORT_STAGE.build(s, M, pts, D.environment);  // stage.js
    return s;
  }
  function updateSkeleton(t) {
    if (!three) return;
    poseAt(t);
    placeSkeleton(three, pts);
    if (three.stage) three.stage.time(three, t, pts);
  }
  /* Move the joints, bones and head of scene s to the positions pts. */
  function placeSkeleton(s, pts) {
    var NP = s.spheres.length;
    for (var i = 0; i < NP; i++) s.spheres[i].position.set(pts[i * 3], pts[i * 3 + 1], pts[i * 3 + 2]);
    for (var k = 0; k < s.bones.length; k++) {
      var bone = s.bones[k];
      s.va.set(pts[bone.a * 3], pts[bone.a * 3 + 1], pts[bone.a * 3 + 2]);
      s.vb.set(pts[bone.b * 3], pts[bone.b * 3 + 1], pts[bone.b * 3 + 2]);
      s.dir.subVectors(s.vb, s.va);
      var len = s.dir.length();
      bone.mesh.position.copy(s.va).addScaledVector(s.dir, 0.5);
      if (len > 1e-6) bone.mesh.quaternion.setFromUnitVectors(s.up, s.dir.divideScalar(len));
      bone.mesh.scale.set(bone.r, Math.max(len, 1e-4), bone.r);
    }
    if (s.head) {
      var h = s.headPoints[0] * 3, e = s.headPoints[1] * 3;
      s.head.position.set((pts[h] + pts[e]) / 2, (pts[h + 1] + pts[e + 1]) / 2, (pts[h + 2] + pts[e + 2]) / 2);
    }
    if (s.stage) s.stage.place(s, pts);
    if ($("follow") && $("follow").checked) {
      // keep the character in view when it walks: move camera and target with the root, on the floor plane
      var dx = pts[0] - s.follow[0], dz = pts[2] - s.follow[2];
      if (dx || dz) {
        s.camera.position.x += dx; s.camera.position.z += dz;
        if (s.controls) { s.controls.target.x += dx; s.controls.target.z += dz; s.controls.update(); }
        s.follow = [pts[0], pts[1], pts[2]];
      }
    }
    s.dirty = true;
  }
  function render() {
    if (three && three.renderer && three.dirty) { three.renderer.render(three.scene, three.camera); three.dirty = false; }
  }

  /* ------------------------------------------------------------------------------------- the timeline */
  var TL = $("timeline"), OV = $("overview");
  var LANE_GAP = 0.3;  // s between two behaviours that share a lane
  var win = { start: 0, width: Math.min(20, duration) };
  (function () {  // as tall as the run needs, at most TL_H: a short run gets a short timeline
    var speechN = D.behaviours.filter(function (b) { return b.speech !== null && b.speech !== undefined; }).length;
    var need = RULER + FEED + 2 + speechN * (SPEECH_H + 2) + (D.words.t.length ? WORDS_H + 2 : 0) +
      (D.behaviours.length - speechN) * 18 + 16;
    TL_H = Math.max(120, Math.min(TL_H, need));
  })();
  var behaviours = D.behaviours.map(function (b, i) {
    var lo = Infinity, hi = -Infinity;
    b.t.forEach(function (x) { if (x !== null) { lo = Math.min(lo, x); hi = Math.max(hi, x); } });
    if (b.stopped !== null) { lo = Math.min(lo, b.stopped); hi = Math.max(hi, b.stopped); }
    var waits = b.inf && b.inf.some(function (x) { return x; });
    if (waits) hi = Infinity;
    // while it really played: up to where it was dropped or cut
    var until = b.stopped !== null ? Math.min(hi, b.stopped) : hi;
    return { b: b, i: i, lo: lo, hi: hi, until: until, speech: b.speech !== null && b.speech !== undefined };
  }).filter(function (x) { return x.lo <= x.hi; });
  (function () {  // pack the behaviours that are not speech into lanes, once: greedily, by start
    var ends = [];
    behaviours.filter(function (x) { return !x.speech; }).sort(function (a, b) { return a.lo - b.lo || a.i - b.i; })
      .forEach(function (x) {
        var lane = ends.findIndex(function (e) { return e + LANE_GAP <= x.lo; });
        if (lane < 0) { lane = ends.length; ends.push(0); }
        ends[lane] = x.hi;
        x.lane = lane;
      });
  })();
  var W = D.words, nWords = W.t.length;
  var F = D.feedback;
  var G = D.gestures, gcol = {};
  G.columns.forEach(function (c, i) { gcol[c] = i; });
  var byName = {};
  G.rows.forEach(function (r) { byName[r[gcol.block] + ":" + r[gcol.behaviour]] = r; });
  function errColour(ms) {
    if (ms === null || ms === undefined) return "#a0aec0";
    var a = Math.abs(ms);
    return a <= 20 ? "#2f855a" : (a <= 80 ? "#dd6b20" : "#c53030");
  }
  function lowerBound(arr, x) {
    var lo = 0, hi = arr.length;
    while (lo < hi) { var mid = (lo + hi) >> 1; if (arr[mid] < x) lo = mid + 1; else hi = mid; }
    return lo;
  }
  function sizeCanvas(c, h) {
    var dpr = window.devicePixelRatio || 1, w = c.parentNode.clientWidth;
    if (c.width !== Math.round(w * dpr) || c.height !== Math.round(h * dpr)) {
      c.width = Math.round(w * dpr); c.height = Math.round(h * dpr);
      c.style.width = w + "px"; c.style.height = h + "px";
    }
    var g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    return { g: g, w: w, h: h };
  }
  function placeWindow(t) {
    if (duration <= win.width) { win.start = 0; return; }
    if (t < win.start || t > win.start + 0.85 * win.width) win.start = clamp(t - 0.15 * win.width, 0, duration - win.width);
    win.start = clamp(win.start, 0, Math.max(0, duration - win.width));
  }
  var layout = null, cursorX = null, cursorT = null;
  function drawTimeline(t) {
    placeWindow(t);
    var c = sizeCanvas(TL, TL_H), g = c.g, w = c.w;
    var t0 = win.start, t1 = win.start + win.width, span = w - LABEL - RIGHT;
    var X = function (x) { return LABEL + (x - t0) / win.width * span; };
    g.clearRect(0, 0, w, TL_H);
    g.font = "11px system-ui, sans-serif";
    g.textBaseline = "middle";
    // ruler
    var step = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 30, 60].find(function (s) { return span / (win.width / s) >= 50; }) || 60;
    g.fillStyle = "#4a5568"; g.strokeStyle = "#e2e8f0"; g.lineWidth = 1;
    for (var s = Math.ceil(t0 / step) * step; s <= t1 + 1e-9; s += step) {
      var xs = Math.round(X(s)) + 0.5;
      g.beginPath(); g.moveTo(xs, RULER - 4); g.lineTo(xs, TL_H); g.stroke();
      g.fillText(s.toFixed(step < 1 ? 1 : 0) + " s", xs + 3, RULER / 2);
    }
    var y = RULER;
    // feedback ticks
    g.fillStyle = "#4a5568"; g.fillText("feedback", 6, y + FEED / 2);
    var f0 = lowerBound(F.t, t0), f1 = lowerBound(F.t, t1 + 1e-9);
    for (var f = f0; f < f1; f++) {
      g.strokeStyle = FEED_COLOURS[F.types[F.kind[f]]] || "#718096";
      var xf = Math.round(X(F.t[f])) + 0.5;
      g.beginPath(); g.moveTo(xf, y + 2); g.lineTo(xf, y + FEED - 1); g.stroke();
    }
    y += FEED + 2;
    var visible = behaviours.filter(function (x) { return x.hi >= t0 && x.lo <= t1; });
    var speechRows = visible.filter(function (x) { return x.speech; });
    var others = visible.filter(function (x) { return !x.speech; });
    var rows = [];
    speechRows.forEach(function (x) { rows.push({ x: x, y: y, h: SPEECH_H }); y += SPEECH_H + 2; });
    var wordsY = y;
    if (nWords) y += WORDS_H + 2;
    var room = TL_H - y - 4, more = 0;
    if (others.length * (ROW_H + 2) <= room) {
      // one row per behaviour, named in the left column
      others.forEach(function (x) { rows.push({ x: x, y: y, h: ROW_H }); y += ROW_H + 2; });
    } else {
      // too many for a row each: behaviours share the lanes they were packed into, named in their bars
      var used = [];
      others.forEach(function (x) { if (used.indexOf(x.lane) < 0) used.push(x.lane); });
      used.sort(function (a, b) { return a - b; });
      var h = clamp(Math.floor(room / Math.max(used.length, 1)) - 2, 10, ROW_H);
      var fit = Math.max(1, Math.floor(room / (h + 2)));
      if (used.length > fit) used = used.slice(0, fit - 1);
      var laneY = {};
      used.forEach(function (lane) { laneY[lane] = y; y += h + 2; });
      others.forEach(function (x) {
        if (laneY[x.lane] === undefined) more++;
        else rows.push({ x: x, y: laneY[x.lane], h: h, packed: true });
      });
      g.fillStyle = "#4a5568";
      g.fillText("behaviours", 6, laneY[used[0]] + h / 2);
      g.fillText("(" + others.length + " in view)", 6, laneY[used[0]] + h / 2 + h + 2);
    }
    rows.forEach(function (r) { drawBehaviour(g, r, X, t0, t1, w); });
    if (more) {
      g.fillStyle = "#718096";
      g.fillText("+ " + more + " more behaviours in this window (zoom in with the wheel)", 6, y + 6);
    }
    // words, as heard
    if (nWords) {
      g.fillStyle = "#4a5568"; g.fillText("words (heard)", 6, wordsY + WORDS_H / 2);
      var w0 = Math.max(0, lowerBound(W.t, t0 - 2)), w1 = lowerBound(W.t, t1 + 1e-9);
      var lastEnd = [-1e9, -1e9, -1e9];
      for (var k = w0; k < w1; k++) {  // the words' spans and onsets first, their names over them
        if (W.end[k] < t0) continue;
        var xa = X(W.t[k]), xb = X(W.end[k]);
        g.fillStyle = W.cut[k] ? "#edf2f7" : (k % 2 ? "#f0fff4" : "#e6f6ec");
        g.fillRect(Math.max(xa, LABEL), wordsY + 1, Math.max(1, xb - Math.max(xa, LABEL)), WORDS_H - 2);
        g.strokeStyle = W.cut[k] ? "#a0aec0" : "#276749";
        g.beginPath(); g.moveTo(Math.round(xa) + 0.5, wordsY); g.lineTo(Math.round(xa) + 0.5, wordsY + WORDS_H); g.stroke();
      }
      g.font = "10px system-ui, sans-serif";
      for (k = w0; k < w1; k++) {
        if (W.end[k] < t0) continue;
        var tx = Math.max(X(W.t[k]) + 2, LABEL + 2), line = lastEnd.findIndex(function (e) { return e <= tx; });
        if (line < 0) continue;  // no room for its name: its onset is still marked
        halo(g, W.text[k], tx, wordsY + 8 + line * 13, W.cut[k] ? "#a0aec0" : "#1a202c");
        lastEnd[line] = tx + g.measureText(W.text[k]).width + 3;
      }
      g.font = "11px system-ui, sans-serif";
    }
    // a stroke meets its word: a line from the gesture's stroke to the word's onset as heard
    g.save(); g.beginPath(); g.rect(LABEL, 0, span, TL_H); g.clip();
    rows.forEach(function (r) {
      var row = byName[r.x.b.name];
      if (!row || !nWords) return;
      var heard = row[gcol.sounded_s], hap = row[gcol.happened_s];
      if (heard === null || heard < t0 - 1 || heard > t1 + 1) return;
      var yw = wordsY + WORDS_H - 2, yr = r.y + r.h / 2;
      g.strokeStyle = errColour(row[gcol.error_ms]); g.lineWidth = 1.5;
      g.beginPath();
      if (hap !== null) { g.moveTo(X(hap), yr); g.lineTo(X(heard), yw); }
      else { g.setLineDash([3, 3]); g.moveTo(X(heard), yr); g.lineTo(X(heard), yw); }
      g.stroke(); g.setLineDash([]); g.lineWidth = 1;
      g.fillStyle = errColour(row[gcol.error_ms]);
      g.beginPath(); g.arc(X(heard), yw, 3, 0, 2 * Math.PI); g.fill();
    });
    g.restore();
    g.clearRect(0, 0, LABEL - 4, RULER);
    // the cursor
    cursorT = t;
    cursorX = X(t);
    g.strokeStyle = "#e53e3e"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(cursorX, 0); g.lineTo(cursorX, TL_H); g.stroke(); g.lineWidth = 1;
    layout = { rows: rows, X: X, t0: t0, span: span, wordsY: wordsY };
    drawOverview(t);
  }
  function drawBehaviour(g, r, X, t0, t1, w) {
    var b = r.x.b, y = r.y, h = r.h, n = b.sync.length;
    var label = b.name + (b.lexeme ? " " + b.lexeme : (b.type !== "gesture" ? " " + b.type : ""));
    if (!r.packed) {
      g.fillStyle = b.dropped ? "#c53030" : "#2d3748";
      g.save(); g.beginPath(); g.rect(0, y, LABEL - 6, h); g.clip();
      g.fillText(label, 6, y + h / 2); g.restore();
    }
    g.save(); g.beginPath(); g.rect(LABEL, y, w - LABEL - RIGHT, h); g.clip();
    var alt = 0;
    for (var i = 0; i + 1 < n; i++) {  // each phase from a known sync point to the next known one
      var a = b.t[i];
      if (a === null) continue;
      var j = i + 1;
      while (j < n && b.t[j] === null && !(b.inf && b.inf[j])) j++;
      if (j >= n) continue;
      var z = b.t[j] === null ? t1 + 1 : b.t[j];  // waiting for the world: on past the window
      var colour = r.x.speech ? (alt++ % 2 ? COLOURS.speech2 : COLOURS.speech) : COLOURS[PHASES[b.sync[i]] || "other"];
      g.globalAlpha = b.passed[j] ? 1 : 0.35;
      g.fillStyle = colour;
      g.fillRect(X(a), y + 1, Math.max(1, X(z) - X(a)), h - 2);
      i = j - 1;
    }
    g.globalAlpha = 1;
    if (b.stopped !== null) {  // dropped or cut while it played: its last phase up to then
      var last = -1;
      for (var q = 0; q < n; q++) if (b.t[q] !== null && b.passed[q] && b.t[q] <= b.stopped) last = q;
      if (last >= 0 && (last + 1 >= n || b.t[last + 1] === null || !b.passed[last + 1])) {
        g.fillStyle = r.x.speech ? COLOURS.speech : COLOURS[PHASES[b.sync[last]] || "other"];
        g.fillRect(X(b.t[last]), y + 1, Math.max(1, X(b.stopped) - X(b.t[last])), h - 2);
      }
    }
    for (var k = 0; k < n; k++) {
      if (b.t[k] === null) continue;
      var x = Math.round(X(b.t[k])) + 0.5;
      var stroke = b.sync[k] === "stroke";
      g.strokeStyle = stroke ? "#1a202c" : "#4a5568"; g.lineWidth = stroke ? 2 : 1;
      g.beginPath(); g.moveTo(x, y + (stroke ? 0 : h / 3)); g.lineTo(x, y + h); g.stroke();
      if (stroke) {
        g.fillStyle = "#1a202c";
        g.beginPath(); g.moveTo(x - 4, y); g.lineTo(x + 4, y); g.lineTo(x, y + 5); g.fill();
      }
    }
    g.lineWidth = 1;
    if (r.packed) {  // the name inside the bar, up to its end
      var xa = Math.max(X(r.x.lo), LABEL) + 3, xb = isFinite(r.x.hi) ? X(r.x.hi) : w;
      g.save(); g.beginPath(); g.rect(xa, y, Math.max(0, xb - xa), h); g.clip();
      g.font = "10px system-ui, sans-serif";
      halo(g, b.name.split(":").pop() + (b.lexeme ? " " + b.lexeme : ""), xa, y + h / 2, b.dropped ? "#c53030" : "#1a202c");
      g.restore();
    }
    if (b.dropped) {
      var xd = X(b.stopped !== null ? b.stopped : r.x.lo);
      g.strokeStyle = "#c53030"; g.lineWidth = 2;
      g.beginPath(); g.moveTo(xd - 4, y + 1); g.lineTo(xd + 4, y + h - 1); g.moveTo(xd + 4, y + 1); g.lineTo(xd - 4, y + h - 1);
      g.stroke(); g.lineWidth = 1;
      halo(g, "dropped" + (b.reason ? ": " + b.reason : ""), xd + 7, y + h / 2, "#c53030");
    } else if (b.stopped !== null) {
      var xc = X(b.stopped);
      g.strokeStyle = "#c53030"; g.lineWidth = 2;
      g.beginPath(); g.moveTo(xc, y); g.lineTo(xc, y + h); g.stroke(); g.lineWidth = 1;
      halo(g, b.interrupted ? "interrupted" : "stopped", xc + 4, y + h / 2, "#c53030");
    }
    g.restore();
  }
  function halo(g, text, x, y, colour) {  // text readable over the bars and ticks under it
    g.lineWidth = 3; g.strokeStyle = "rgba(255,255,255,0.85)"; g.lineJoin = "round";
    g.strokeText(text, x, y);
    g.fillStyle = colour; g.fillText(text, x, y); g.lineWidth = 1;
  }
  var overview = null;
  function buildOverview(w) {
    var c = document.createElement("canvas"), dpr = window.devicePixelRatio || 1;
    c.width = Math.round(w * dpr); c.height = Math.round(OV_H * dpr);
    var g = c.getContext("2d");
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    var span = w - LABEL - RIGHT, X = function (x) { return LABEL + x / duration * span; };
    g.fillStyle = "#f7fafc"; g.fillRect(LABEL, 0, span, OV_H);
    g.font = "11px system-ui, sans-serif"; g.textBaseline = "middle"; g.fillStyle = "#4a5568";
    g.fillText("whole run (" + duration.toFixed(1) + " s)", 6, OV_H / 2);
    behaviours.forEach(function (x) {
      if (!x.speech || !isFinite(x.lo)) return;
      g.fillStyle = COLOURS.speech; g.fillRect(X(x.lo), 4, Math.max(1, X(Math.min(x.hi, duration)) - X(x.lo)), 10);
    });
    G.rows.forEach(function (r) {
      var tt = rowTime(r);
      if (tt === null) return;
      g.fillStyle = r[gcol.dropped] ? "#c53030" : errColour(r[gcol.error_ms]);
      g.fillRect(X(tt), 17, 1, r[gcol.dropped] ? 14 : 10);
    });
    behaviours.forEach(function (x) {
      if (x.b.dropped && !byName[x.b.name]) { g.fillStyle = "#c53030"; g.fillRect(X(isFinite(x.lo) ? x.lo : 0), 17, 1, 14); }
    });
    D.warnings.forEach(function (wn) { g.fillStyle = "#e53e3e"; g.fillRect(X(wn.t), OV_H - 10, 1, 8); });
    return { canvas: c, w: w, X: X };
  }
  function drawOverview(t) {
    var c = sizeCanvas(OV, OV_H), g = c.g;
    if (!overview || overview.w !== c.w) overview = buildOverview(c.w);
    g.clearRect(0, 0, c.w, OV_H);
    g.drawImage(overview.canvas, 0, 0, c.w, OV_H);
    var X = overview.X;
    g.strokeStyle = "#2b6cb0"; g.lineWidth = 1.5;
    g.strokeRect(X(win.start), 1, Math.max(2, X(win.start + win.width) - X(win.start)), OV_H - 2);
    g.strokeStyle = "#e53e3e"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(X(t), 0); g.lineTo(X(t), OV_H); g.stroke(); g.lineWidth = 1;
  }
  function timeAt(canvas, event, whole) {
    var box = canvas.getBoundingClientRect(), x = event.clientX - box.left;
    var span = box.width - LABEL - RIGHT;
    if (x < LABEL) return null;
    return whole ? (x - LABEL) / span * duration : win.start + (x - LABEL) / span * win.width;
  }
  TL.addEventListener("click", function (e) { var t = timeAt(TL, e, false); if (t !== null) seek(t); });
  var dragging = false;
  OV.addEventListener("mousedown", function (e) { var t = timeAt(OV, e, true); if (t !== null) { dragging = true; seek(t); } });
  window.addEventListener("mousemove", function (e) { if (dragging) { var t = timeAt(OV, e, true); if (t !== null) seek(t); } });
  window.addEventListener("mouseup", function () { dragging = false; });
  TL.addEventListener("wheel", function (e) {
    e.preventDefault();
    var t = now();
    win.width = clamp(win.width * (e.deltaY > 0 ? 1.25 : 0.8), 1, Math.max(duration, 1));
    win.start = clamp(t - 0.15 * win.width, 0, Math.max(0, duration - win.width));
    draw(true);
  }, { passive: false });
  TL.addEventListener("mousemove", function (e) {
    if (!layout) return;
    var box = TL.getBoundingClientRect(), y = e.clientY - box.top, t = timeAt(TL, e, false), text = "";
    var r = layout.rows.find(function (r) {
      return y >= r.y && y < r.y + r.h + 2 && (!r.packed || (t !== null && t >= r.x.lo - 0.1 && t <= r.x.hi + 0.1));
    });
    if (r) {
      var b = r.x.b, best = -1;
      if (t !== null) b.t.forEach(function (x, i) { if (x !== null && (best < 0 || Math.abs(x - t) < Math.abs(b.t[best] - t))) best = i; });
      text = b.name + " (" + b.type + (b.lexeme ? " " + b.lexeme : "") + ", " + b.state + ")";
      if (best >= 0) text += ": " + b.sync[best] + " at " + fmt(b.t[best]) + " s" + (b.passed[best] ? "" : " (planned, not reached)");
      var row = byName[b.name];
      if (row && row[gcol.error_ms] !== null) text += "; tied to '" + row[gcol.word] + "', error " + fmt(row[gcol.error_ms], 1) + " ms";
      if (b.dropped) text += "; dropped" + (b.reason ? ": " + b.reason : "");
    } else if (t !== null && y >= layout.wordsY && y < layout.wordsY + WORDS_H) {
      var k = lowerBound(W.t, t) - 1;
      if (k >= 0 && t <= W.end[k]) text = "'" + W.text[k] + "' heard " + fmt(W.t[k]) + "-" + fmt(W.end[k]) + " s" + (W.cut[k] ? " (cut)" : "");
    }
    if (!text && t !== null) text = fmt(t) + " s";
    $("hover").textContent = text || "\u00a0";
  });

  /* ------------------------------------------------------------------------------------- the table */
  var tbody = document.querySelector("#gestures tbody"), trs = [], current = null;
  var sortState = { col: null, dir: 1 };
  function rowTime(r) {
    if (r[gcol.happened_s] !== null) return r[gcol.happened_s];
    if (r[gcol.sounded_s] !== null) return r[gcol.sounded_s];
    var b = behaviours.find(function (x) { return x.b.name === r[gcol.block] + ":" + r[gcol.behaviour]; });
    return b && isFinite(b.lo) ? b.lo : null;
  }
  function buildTable() {
    var head = document.createElement("tr");
    G.headings.forEach(function (hd, i) {
      var th = document.createElement("th");
      th.textContent = hd;
      th.addEventListener("click", function () { sortBy(i); });
      head.appendChild(th);
    });
    document.querySelector("#gestures thead").appendChild(head);
    var frag = document.createDocumentFragment();
    G.rows.forEach(function (r, i) {
      var tr = document.createElement("tr");
      tr.dataset.index = i;
      r.forEach(function (v, c) {
        var td = document.createElement("td"), col = G.columns[c];
        if (v === null) td.textContent = "";
        else if (col === "dropped") td.textContent = v ? "yes" : "";
        else if (col === "error_ms") { td.textContent = v.toFixed(1); td.style.color = errColour(v); }
        else if (typeof v === "number") td.textContent = v.toFixed(3);
        else td.textContent = v;
        if (typeof v === "number") td.className = "num";
        tr.appendChild(td);
      });
      if (r[gcol.dropped]) tr.className = "dropped";
      tr.addEventListener("click", function () { var t = rowTime(r); if (t !== null) seek(t); });
      trs.push({ tr: tr, t: rowTime(r) });
      frag.appendChild(tr);
    });
    tbody.appendChild(frag);
    if (!G.rows.length) {
      var tr = document.createElement("tr"), td = document.createElement("td");
      td.colSpan = G.columns.length; td.textContent = "no behaviour of this run is pegged to a word or a beat";
      tr.appendChild(td); tbody.appendChild(tr);
    }
  }
  function sortBy(c) {
    sortState.dir = sortState.col === c ? -sortState.dir : 1;
    sortState.col = c;
    var order = G.rows.map(function (_, i) { return i; });
    order.sort(function (a, b) {
      var x = G.rows[a][c], y = G.rows[b][c];
      if (x === y) return a - b;
      if (x === null) return 1;
      if (y === null) return -1;
      if (G.columns[c] === "error_ms") { x = Math.abs(x); y = Math.abs(y); }
      return (x < y ? -1 : 1) * sortState.dir;
    });
    order.forEach(function (i) { tbody.appendChild(trs[i].tr); });
    document.querySelectorAll("#gestures th").forEach(function (th, i) {
      th.className = i === c ? (sortState.dir > 0 ? "asc" : "desc") : "";
    });
  }
  function markCurrent(t) {
    var best = null, dist = 0.3;
    for (var i = 0; i < trs.length; i++) {
      if (trs[i].t === null) continue;
      var d = Math.abs(trs[i].t - t);
      if (d < dist - 1e-9) { dist = d; best = i; }
    }
    if (best === current) return;
    if (current !== null) trs[current].tr.classList.remove("current");
    if (best !== null) trs[best].tr.classList.add("current");
    current = best;
  }

  /* ------------------------------------------------------------------------------------- the panels */
  var nowText = "";
  function updateNow(t) {
    var lines = [];
    var k = lowerBound(W.t, t + 1e-3) - 1;  // a stroke at a word's onset shows that word
    if (k >= 0 && t <= W.end[k]) lines.push("word: <b>" + esc(W.text[k]) + "</b>" + (W.cut[k] ? " (cut)" : ""));
    var active = behaviours.filter(function (x) { return !x.speech && x.lo <= t && t <= x.until; });
    active.slice(0, 8).forEach(function (x) {
      var b = x.b, phase = "";
      for (var i = 0; i + 1 < b.sync.length; i++) {
        if (b.t[i] !== null && b.t[i] <= t && (b.t[i + 1] === null || t < b.t[i + 1])) { phase = PHASES[b.sync[i]] || b.sync[i]; break; }
      }
      lines.push(esc(b.name) + " " + esc(b.lexeme || b.type) + (phase ? ": " + phase : "") + (b.dropped ? " <span class=dropped>(dropped)</span>" : ""));
    });
    if (active.length > 8) lines.push("+ " + (active.length - 8) + " more");
    var text = lines.join("<br>");
    if (text !== nowText) { $("now").innerHTML = text; nowText = text; }
  }
  function esc(s) { return String(s).replace(/[&<>"]/g, function (c) { return { "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" }[c]; }); }
  function legend() {
    var items = [["stroke", "stroke (triangle: stroke point)"], ["preparation", "preparation, retraction"],
      ["pre-stroke hold", "holds"], ["speech", "speech"]];
    var html = items.map(function (x) { return "<span><i style=\"background:" + COLOURS[x[0]] + "\"></i>" + x[1] + "</span>"; }).join("");
    html += "<span><i style=\"background:#2f855a\"></i>stroke to word: |error| &le; 20 ms</span>" +
      "<span><i style=\"background:#dd6b20\"></i>&le; 80 ms</span><span><i style=\"background:#c53030\"></i>more, or dropped</span>" +
      "<span><i style=\"background:#e53e3e\"></i>cursor, warnings</span>";
    if (M) html += "<label><input type=checkbox id=follow checked> camera follows the character</label>";
    $("legend").innerHTML = html;
  }
  function summaryText() {
    var s = D.summary, parts = [];
    parts.push(D.behaviours.length + " behaviours");
    parts.push(duration.toFixed(2) + " s");
    if (D.audio) parts.push("sound " + D.audio.duration.toFixed(2) + " s at " + D.audio.rate + " Hz");
    if (M) parts.push("motion " + M.frames + " frames at " + M.fps + " fps (" + M.sent + " sent, " + M.points.length + " points)");
    var g = s.gestures + " pegged behaviours";
    if (s.measured) g += ", " + s.measured + " measured: |error| median " + s.median_ms.toFixed(1) + " ms, 95th percentile " +
      s.p95_ms.toFixed(1) + " ms, max " + s.max_ms.toFixed(1) + " ms";
    if (s.dropped) g += ", " + s.dropped + " dropped";
    parts.push(g);
    if (D.drops.length) parts.push(D.drops.length + " drops");
    if (D.warnings.length) parts.push(D.warnings.length + " warnings");
    $("summary").textContent = parts.join(" \u00b7 ");
  }

  /* ------------------------------------------------------------------------------------- drawing */
  var drawnAt = null;
  function draw(force) {
    var t = now();
    if (!force && t === drawnAt) return;
    drawnAt = t;
    updateSkeleton(t);
    drawTimeline(t);
    markCurrent(t);
    updateNow(t);
    $("clock").textContent = t.toFixed(3) + " s / " + duration.toFixed(3) + " s";
    if (document.activeElement !== scrub) scrub.value = String(t);
    render();
  }
  function loop() {
    draw(false);
    render();
    requestAnimationFrame(loop);
  }

  api.duration = function () { return duration; };
  api.seek = seek;
  api.time = now;
  api.play = play;
  api.pause = pause;
  api.playing = playing;
  api.cursor = function () { return cursorX; };
  api.cursorTime = function () { return cursorT; };
  api.window = function () { return [win.start, win.start + win.width]; };
  api.joint = function (name) { return jointPosition(three, M, name); };
  api.environment = function () { return three && three.stage ? three.stage.state(three) : null; };

  try {
    summaryText();
    legend();
    buildTable();
    if (M && P) { poseAt(M.start); three = buildScene(M, pts); }
    window.addEventListener("resize", function () { overview = null; draw(true); });
    draw(true);
    requestAnimationFrame(loop);
  } catch (e) {
    errors.push("report.js: " + e.message);
    throw e;
  }
  function done() { if (!api.ready) { api.ready = true; document.body.classList.add("ready"); } }
  if (audio && audio.readyState < 1) {
    audio.addEventListener("loadedmetadata", function () { draw(true); done(); });
    audio.addEventListener("error", function () { errors.push("the audio did not load"); done(); });
    setTimeout(done, 10000);
  } else {
    done();
  }
  /* ------------------------------------------------------------------------------------- live */
  /* The live viewer: the page agentsim serve serves at / (agentsim.live.poses has the messages).

     It opens a WebSocket to options.url (by default the page's own host and port, with the page's ?token=
     if it has one), sends
     {"subscribe": ["poses", "feedback"]}, builds the skeleton from the server's "skeleton" message and buffers the frames
     of its "poses" messages. A message comes when its last frame is due on the server's clock, a few frames
     at a time; the page plays the frames at a steady delay (hold) behind the newest time it can know, so
     that motion is smooth: the server's clock is read as the page's clock minus the smallest lag seen lately
     between a message's arrival and the time of what it carries. When frames come later than the hold
     allows for (the buffer runs dry: the last frame is held), the hold grows by 50 ms, up to 1 s; after
     30 s without that it shrinks again by 50 ms, down to a period and 0.1 s. Feedback (every client's: it subscribes) is
     applied when the play time reaches its globalTime: a timeline of the behaviours (planned phases pale,
     passed ones solid), what plays now, and a list. When the server goes away the page says so, keeps the
     last pose and tries again every few seconds; a new connection starts afresh (a new server has a new
     clock).

     window.report.live is its state for tests: url, state ("connecting", "connected", "disconnected"),
     connected, skeleton (the skeleton message arrived), connections (opened so far), closed (the code of
     the last close); and of the current connection: messages and frames received, first (the first
     frame's index), gaps and repeats (frames missing or sent twice between messages), stalls (the buffer
     ran dry), feedback, warnings, time (the play time, s of the server's clock), latest (the newest
     frame's time), hold (s), lag (s: arrival minus time, the smallest lately). report.time() and
     report.joint(name) are as in the report; report.watch(name) records [time, x, y, z, between] of that
     joint at every frame drawn from then on (between: 1 if drawn between two frames received, 0 if held on
     the first or the last one), report.watched(name) returns them. */
  // The world position [x, y, z] of skeleton point ``name`` as drawn in ``three`` (null before a scene).
  function jointPosition(three, M, name) {
    if (!three || !M) return null;
    var i = M.points.indexOf(name);
    if (i < 0) return null;
    var p = three.spheres[i].position;
    return [p.x, p.y, p.z];
  }

  function live(options) {
    var host = location.host || "127.0.0.1:8765";
    var token = new URLSearchParams(location.search).get("token");  // a server with a token: pass it on
    var url = options.url || ((location.protocol === "https:" ? "wss://" : "ws://") + host + "/" +
      (token ? "?token=" + encodeURIComponent(token) : ""));
    var NONE = 0, BETWEEN = 1, HELD = 2;
    var HOLD = 0.2, RETRY = [1, 2, 3, 5], LAGS = 50, KEEP = 3, WINDOW = 10, AHEAD = 2, FEED_ITEMS = 60, WATCH = 50000;
    var state = { url: url, state: "connecting", connected: false, skeleton: false, connections: 0, messages: 0,
      frames: 0, first: null, gaps: 0, repeats: 0, stalls: 0, feedback: 0, warnings: 0, time: null, latest: null,
      hold: HOLD, lag: null, closed: null, fps: null, period: null };
    var socket = null, attempt = 0, retryAt = null;
    var M = null, rest = null, pts = null;
    var ft = [], fp = [], next = null, stalled = false;  // frame times and positions; next index expected
    var lags = [], lastPlay = null, base = HOLD, steady = 0;  // steady: since when no frame came late (ms)
    var pending = [], beh = {}, behOrder = 0, ticks = [], blocks = {};
    var watches = {};
    //: the environment's rows (stage.js), the one before any emotion first
    var environment = [{ t: -Infinity, emotion: "none", intensity: 0, shot: "full", angle: "eye", key: [255, 255, 255],
      attenuation: 0.5, valence: "none", music: "" }];
    api.live = state;

    /* ------------------------------------------------ the page */
    $("endpoint").textContent = url;
    var feedList = $("feed");
    function status() {
      var el = $("status"), text;
      if (state.state === "connected") {
        text = "connected to " + url + (state.fps ? " \u00b7 poses at " + state.fps + " fps" : "") +
          " \u00b7 " + state.frames + " frames received" + (state.lag !== null ? " \u00b7 playing " +
          (state.hold).toFixed(2) + " s behind the server" : "");
      } else if (state.state === "disconnected") {
        var wait = retryAt === null ? 0 : Math.max(0, Math.ceil((retryAt - performance.now()) / 1000));
        text = "disconnected: " + (state.connections ? "the server at " + url + " went away" : "no server at " + url) +
          (state.closed !== null ? " (code " + state.closed + ")" : "") + "; trying again" +
          (wait ? " in " + wait + " s" : " now") + " (attempt " + attempt + ")";
      } else {
        text = "connecting to " + url + "\u2026";
      }
      if (el.textContent !== text) el.textContent = text;
      el.className = "status " + state.state;
      document.body.classList.toggle("connected", state.connected);
    }
    (function legendLive() {
      var items = [["stroke", "stroke (triangle: stroke point)"], ["preparation", "preparation, retraction"],
        ["pre-stroke hold", "holds"], ["speech", "speech"]];
      $("legend").innerHTML = items.map(function (x) {
        return "<span><i style=\"background:" + COLOURS[x[0]] + "\"></i>" + x[1] + "</span>";
      }).join("") + "<span>pale: planned; solid: passed</span><span><i style=\"background:#e53e3e\"></i>now, warnings</span>" +
        "<label><input type=checkbox id=follow checked> camera follows the character</label>";
    })();

    /* ------------------------------------------------ the connection */
    function connect() {
      retryAt = null;
      state.state = "connecting";
      status();
      var ws;
      try {
        ws = new WebSocket(url);
      } catch (e) {  // a malformed address: say so, and try no more
        state.state = "disconnected";
        $("status").textContent = "cannot connect to " + url + ": " + e.message;
        return;
      }
      socket = ws;
      ws.onopen = function () {
        if (ws !== socket) return;
        attempt = 0;
        state.connections++;
        state.connected = true;
        state.state = "connected";
        state.closed = null;
        afresh();
        ws.send(JSON.stringify({ subscribe: ["poses", "feedback"] }));  // every client's feedback
        status();
      };
      ws.onmessage = function (event) {
        if (ws !== socket) return;
        try {
          receive(JSON.parse(event.data), performance.now() / 1000);
        } catch (e) {
          errors.push("report.js: live message: " + e.message);
          throw e;
        }
      };
      ws.onclose = function (event) {
        if (ws !== socket) return;
        socket = null;
        state.connected = false;
        state.state = "disconnected";
        state.closed = event.code;
        var wait = RETRY[Math.min(attempt, RETRY.length - 1)];
        attempt++;
        retryAt = performance.now() + wait * 1000;
        setTimeout(connect, wait * 1000);
        note(state.connections ? "disconnected" : "no server");
        status();
      };
      ws.onerror = function () {};  // a close follows, which says what to do
    }
    function afresh() {  // a new connection: a new clock, a new run
      ft = []; fp = []; next = null; stalled = false; lags = []; lastPlay = null;
      pending = []; beh = {}; ticks = []; blocks = {};
      ["messages", "frames", "gaps", "repeats", "stalls", "feedback", "warnings"].forEach(function (k) { state[k] = 0; });
      state.first = state.time = state.latest = state.lag = null;
      state.hold = base = HOLD;
      steady = performance.now();
      if (state.connections > 1) note("connected again");
    }
    function note(text) {
      var li = document.createElement("li");
      li.className = "mark";
      li.textContent = "\u2014 " + text + " \u2014";
      feedList.insertBefore(li, feedList.firstChild);
    }

    /* ------------------------------------------------ messages */
    function lagSample(arrival, t) {
      lags.push(arrival - t);
      if (lags.length > LAGS) lags.shift();
      state.lag = Math.min.apply(null, lags);
    }
    function receive(m, arrival) {
      state.messages++;
      if (m.type === "skeleton") return skeleton(m);
      if (m.type === "poses") return poses(m, arrival);
      if (m.type === "environment") {  // a change of the camera and the lights, shown from its time on
        environment.push({ t: m.globalTime, emotion: m.emotion, intensity: m.intensity, shot: m.shot, angle: m.angle,
          key: m.key, attenuation: m.attenuation, valence: m.valence, music: "" });
        return;
      }
      state.feedback++;
      if (typeof m.globalTime === "number") lagSample(arrival, m.globalTime);
      pending.push(m);
    }
    function skeleton(m) {
      var same = M && M.points.length === m.joints.length && M.points.every(function (n, i) { return n === m.joints[i]; });
      M = { points: m.joints, parents: m.parents, face: m.face, ends: m.ends };
      rest = new Float64Array([].concat.apply([], m.rest));
      state.fps = m.fps;
      state.period = m.period;
      base = Math.max(HOLD, m.period + 0.1);
      state.hold = Math.max(state.hold, base);
      if (!same) {
        if (three && three.renderer) three.renderer.domElement.remove();
        pts = new Float64Array(rest);
        three = buildScene(M, pts);
        if (three && m.segments && window.REPORT_STAGE) {  // the body as solid segments, filmed and lit (stage.js)
          window.REPORT_STAGE.build(three, M, pts, { rows: environment, segments: m.segments });
        }
        if (three) placeSkeleton(three, pts);
      }
      state.skeleton = true;
    }
    function poses(m, arrival) {
      var n = m.frames.length, first = 0;
      if (!n) return;
      if (next !== null && m.index !== next) {
        if (m.index > next) state.gaps++;
        else { state.repeats++; first = next - m.index; }
      }
      for (var k = first; k < n; k++) {
        ft.push((m.index + k) / m.fps);
        fp.push(new Float32Array(m.frames[k]));
      }
      next = m.index + n;
      if (state.first === null) state.first = m.index;
      state.frames += n;
      state.latest = (m.index + n - 1) / m.fps;
      lagSample(arrival, state.latest);
    }
    function playTime(clock) {
      if (state.lag === null) return null;
      if (state.hold > base && clock * 1000 - steady > 30000) {  // frames came in time for 30 s: come closer
        state.hold = Math.max(base, state.hold - 0.05);
        steady = clock * 1000;
      }
      var t = clock - state.lag - state.hold;
      if (!state.connected && state.latest !== null && t > state.latest) t = state.latest;  // the server is gone
      if (lastPlay !== null && t < lastPlay) t = lastPlay;  // never backwards
      lastPlay = t;
      return t;
    }
    function poseAt(t) {  // the buffered frames around t, linearly between them: BETWEEN; HELD: the first or
      var n = ft.length;  // the last one, t being outside them; NONE: no frame yet (the rest pose stays)
      if (!n || t === null) return NONE;
      if (t > ft[n - 1]) {
        if (!stalled && state.connected) {
          stalled = true;
          state.stalls++;
          state.hold = Math.min(1.0, state.hold + 0.05);  // the frames came later than the hold allowed for
          steady = performance.now();
        }
        pts.set(fp[n - 1]);
        return HELD;
      }
      stalled = false;
      if (t < ft[0]) { pts.set(fp[0]); return HELD; }
      var lo = 0, hi = n - 1;
      while (hi - lo > 1) { var mid = (lo + hi) >> 1; if (ft[mid] <= t) lo = mid; else hi = mid; }
      var w = hi > lo ? (t - ft[lo]) / (ft[hi] - ft[lo]) : 0, a = fp[lo], b = fp[hi];
      for (var q = 0; q < pts.length; q++) pts[q] = a[q] * (1 - w) + b[q] * w;
      return BETWEEN;
    }
    function trim(t) {  // frames older than KEEP s behind the play time go
      var k = 0;
      while (k < ft.length - 2 && ft[k + 1] < t - KEEP) k++;
      if (k) { ft.splice(0, k); fp.splice(0, k); }
    }

    /* ------------------------------------------------ feedback: the timeline, the panels, the list */
    function behaviour(block, id) {
      var name = block + ":" + id;
      if (!beh[name]) beh[name] = { name: name, type: "", lexeme: null, sync: [], t: [], passed: [], inf: null,
        stopped: null, dropped: false, order: behOrder++ };
      return beh[name];
    }
    function setSync(b, sync, t, passed) {
      var i = b.sync.indexOf(sync);
      if (i < 0) {
        i = 0;
        while (i < b.sync.length && b.t[i] !== null && b.t[i] <= t) i++;
        b.sync.splice(i, 0, sync); b.t.splice(i, 0, t); b.passed.splice(i, 0, passed);
      } else if (!b.passed[i] || passed) {
        b.t[i] = t; b.passed[i] = b.passed[i] || passed;
      }
    }
    function apply(m) {
      var t = m.globalTime;
      ticks.push({ t: t, type: m.type });
      if (m.type === "predictionFeedback" && m.behaviours) {
        m.behaviours.forEach(function (p) {
          var b = behaviour(m.id, p.id);
          b.type = p.type || b.type;
          Object.keys(p.syncs || {}).forEach(function (sync) {
            if (typeof p.syncs[sync] === "number") setSync(b, sync, p.syncs[sync], false);
          });
        });
        blocks[m.id] = blocks[m.id] || {};
      } else if (m.type === "syncPointProgress") {
        var parts = m.id.split(":");
        if (parts.length >= 3) setSync(behaviour(parts[0], parts[1]), parts.slice(2).join(":"), t, true);
      } else if (m.type === "blockProgress") {
        var bp = m.id.split(":"), block = blocks[bp[0]] = blocks[bp[0]] || {};
        block[bp[1]] = t;
      } else if (m.type === "warningFeedback") {
        state.warnings++;
      }
      listItem(m);
    }
    function listItem(m) {
      var li = document.createElement("li"), text = fmt(m.globalTime) + " s  ";
      if (m.type === "syncPointProgress") text += m.id;
      else if (m.type === "blockProgress") text += "block " + m.id;
      else if (m.type === "predictionFeedback") text += "plan of " + m.id + (m.bml ? ": " + fmt(m.bml.globalStart) +
        "\u2013" + fmt(m.bml.globalEnd) + " s" : "");
      else if (m.type === "warningFeedback") { text += (m.warningType || "warning") + " " + m.id + ": " + (m.description || ""); li.className = "warning"; }
      else text += m.type + " " + (m.id || "");
      li.textContent = text;
      if (/:stroke$/.test(m.id || "")) li.className = "stroke";
      feedList.insertBefore(li, feedList.firstChild);
      while (feedList.children.length > FEED_ITEMS) feedList.removeChild(feedList.lastChild);
    }
    function span(b) {
      var lo = Infinity, hi = -Infinity;
      b.t.forEach(function (x) { if (x !== null) { lo = Math.min(lo, x); hi = Math.max(hi, x); } });
      return [lo, hi];
    }
    function forget(t) {  // what ended long ago
      while (ticks.length && ticks[0].t < t - 2 * WINDOW) ticks.shift();
      Object.keys(beh).forEach(function (k) { if (span(beh[k])[1] < t - 2 * WINDOW) delete beh[k]; });
    }
    function drawLive(t) {
      var H = 210, c = sizeCanvas($("timeline"), H), g = c.g, w = c.w;
      var t0 = Math.max(0, t + AHEAD - WINDOW), t1 = t0 + WINDOW, span0 = w - LABEL - RIGHT;
      var X = function (x) { return LABEL + (x - t0) / WINDOW * span0; };
      g.clearRect(0, 0, w, H);
      g.font = "11px system-ui, sans-serif";
      g.textBaseline = "middle";
      g.fillStyle = "#4a5568"; g.strokeStyle = "#e2e8f0"; g.lineWidth = 1;
      for (var s = Math.ceil(t0); s <= t1 + 1e-9; s += 1) {
        var xs = Math.round(X(s)) + 0.5;
        g.beginPath(); g.moveTo(xs, RULER - 4); g.lineTo(xs, H); g.stroke();
        g.fillText(s.toFixed(0) + " s", xs + 3, RULER / 2);
      }
      var y = RULER;
      g.fillStyle = "#4a5568"; g.fillText("feedback", 6, y + FEED / 2);
      ticks.forEach(function (k) {
        if (k.t < t0 || k.t > t1) return;
        g.strokeStyle = FEED_COLOURS[k.type] || "#718096";
        var xf = Math.round(X(k.t)) + 0.5;
        g.beginPath(); g.moveTo(xf, y + 2); g.lineTo(xf, y + FEED - 1); g.stroke();
      });
      y += FEED + 2;
      var rows = Object.keys(beh).map(function (k) { return beh[k]; }).map(function (b) {
        var sp = span(b);
        return { b: b, lo: sp[0], hi: sp[1], until: sp[1], speech: b.type === "speech" };
      }).filter(function (x) { return x.hi >= t0 && x.lo <= t1; }).sort(function (a, b) {
        return (b.speech - a.speech) || (a.lo - b.lo) || (a.b.order - b.b.order);
      });
      var fit = Math.max(1, Math.floor((H - y - 2) / (ROW_H + 2)));
      if (rows.length > fit) rows = rows.slice(rows.length - fit);
      rows.forEach(function (x) {
        drawBehaviour(g, { x: x, y: y, h: ROW_H }, X, t0, t1, w);
        y += ROW_H + 2;
      });
      if (!rows.length) { g.fillStyle = "#718096"; g.fillText("nothing has played in the last " + WINDOW + " s: send BML to " + url, LABEL + 6, y + 8); }
      g.clearRect(0, 0, LABEL - 4, RULER);
      g.strokeStyle = "#e53e3e"; g.lineWidth = 2;
      var xc = X(t);
      g.beginPath(); g.moveTo(xc, 0); g.lineTo(xc, H); g.stroke(); g.lineWidth = 1;
      return rows;
    }
    var nowText = null;
    function nowPanel(t, rows) {
      var lines = [];
      Object.keys(blocks).forEach(function (id) {
        var b = blocks[id];
        if (b.start !== undefined && b.end === undefined) lines.push("block <b>" + esc(id) + "</b> playing");
      });
      rows.filter(function (x) { return x.lo <= t && t <= x.hi && !x.b.passed[x.b.passed.length - 1]; }).slice(0, 8)
        .forEach(function (x) {
          var b = x.b, phase = "";
          for (var i = 0; i + 1 < b.sync.length; i++) {
            if (b.t[i] !== null && b.t[i] <= t && t < b.t[i + 1]) { phase = x.speech ? "" : (PHASES[b.sync[i]] || b.sync[i]); break; }
          }
          lines.push(esc(b.name) + " " + esc(b.type) + (phase ? ": " + phase : ""));
        });
      var text = lines.length ? lines.join("<br>") : "idle";
      if (text !== nowText) { $("now").innerHTML = text; nowText = text; }
    }

    /* ------------------------------------------------ every frame */
    var shownAt = 0;
    function tick() {
      var t = playTime(performance.now() / 1000);
      if (t !== null) {
        state.time = t;
        while (pending.length && pending[0].globalTime <= t) apply(pending.shift());
        var how = three ? poseAt(t) : NONE;
        if (how !== NONE) placeSkeleton(three, pts);
        if (three && three.stage) three.stage.time(three, t, pts);
        trim(t);
        forget(t);
        Object.keys(watches).forEach(function (name) {
          var i = M ? M.points.indexOf(name) : -1, list = watches[name];
          if (i < 0 || !three || list.length >= WATCH) return;
          if (list.length && list[list.length - 1][0] === t) return;
          var p = three.spheres[i].position;
          list.push([t, p.x, p.y, p.z, how === BETWEEN ? 1 : 0]);
        });
      }
      var rows = drawLive(t === null ? 0 : t);
      nowPanel(t === null ? 0 : t, rows);
      var clockNow = performance.now();
      if (clockNow - shownAt > 250) {
        shownAt = clockNow;
        $("clock").textContent = t === null ? "waiting for the server's clock" : t.toFixed(3) + " s";
        status();
      }
      render();
    }
    function loop() {
      requestAnimationFrame(loop);
      try { tick(); } catch (e) { errors.push("report.js: live: " + e.message); throw e; }
    }

    api.time = function () { return state.time; };
    api.joint = function (name) { return jointPosition(three, M, name); };
    api.watch = function (name) { watches[name] = []; return true; };
    api.watched = function (name) { return watches[name] || null; };
    api.environment = function () { return three && three.stage ? three.stage.state(three) : null; };
    window.addEventListener("resize", function () { if (three) three.dirty = true; });
    status();
    connect();
    requestAnimationFrame(loop);
    api.ready = true;
    document.body.classList.add("ready");
  }
})();
