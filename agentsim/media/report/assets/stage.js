/* agentsim run report: the stage of a run with emotions (agentsim.media.environment, agentsim.expression).

   report.js calls window.REPORT_STAGE.build(s, M, pts, env) once its 3D scene s is made, when the report's
   data holds an environment: the body is then drawn as solid, shaded capsules (the radii of the physical
   model's segments, fingers and all), a head with eyes, brows, nose and lips, lit by three-point lighting
   (a key light between the camera and the character, a fill light and a back light) and filmed as the
   environment's rows say: at each row (a change of the strongest emotion) the camera cuts to its shot
   (full, medium, close-up, extreme close-up) and angle (eye, low, high), and the key light takes its
   colour and its attenuation (brightness 1 - attenuation). report.environment() says what is shown. */
(function () {
  "use strict";

  var SKIN = 0xd9d2c8, FOV = 32, HEAD_R = 0.11;
  //: Half the height of what each shot frames (m) and where it aims: the body, the waist up, the face, the eyes.
  var SHOTS = { full: 1.05, medium: 0.55, "close-up": 0.21, "extreme-close-up": 0.09 };
  //: The camera's elevation above (high) or below (low) its target (degrees).
  var ANGLES = { eye: 0, high: 35, low: -25 };

  function build(s, M, pts, env) {
    var T = s.T, names = M.points;
    var idx = function (n) { return names.indexOf(n); };
    var st = { env: env, row: -1, segments: [], features: [], T: T };
    s.stage = st;
    s.scene.background = new T.Color(0x1d222b);
    s.scene.children.slice().forEach(function (o) { if (o.isLight) o.visible = false; });
    s.spheres.forEach(function (m) { m.visible = false; });
    s.bones.forEach(function (b) { b.mesh.visible = false; });
    if (s.head) s.head.visible = false;
    var skin = new T.MeshStandardMaterial({ color: SKIN, roughness: 0.55, metalness: 0.0 });
    env.segments.forEach(function (seg) {
      var a = seg[0], b = seg[1], r = seg[2];
      var len = Math.hypot(pts[b * 3] - pts[a * 3], pts[b * 3 + 1] - pts[a * 3 + 1], pts[b * 3 + 2] - pts[a * 3 + 2]);
      var mesh = new T.Mesh(new T.CapsuleGeometry(r, Math.max(len, 1e-3), 4, 14), skin);
      s.scene.add(mesh);
      st.segments.push({ mesh: mesh, a: a, b: b });
    });
    st.top = idx("skullbase.end"); st.base = idx("skullbase");
    st.head = new T.Mesh(new T.SphereGeometry(HEAD_R, 32, 24), skin);
    s.scene.add(st.head);
    var white = new T.MeshStandardMaterial({ color: 0xf4f4f0, roughness: 0.3 });
    var dark = new T.MeshStandardMaterial({ color: 0x2a1d14, roughness: 0.4 });
    var lips = new T.MeshStandardMaterial({ color: 0xa8504a, roughness: 0.5 });
    var nose = new T.MeshStandardMaterial({ color: SKIN, roughness: 0.55 });
    function feature(geo, mat, at, out) { var m = new T.Mesh(geo, mat); s.scene.add(m); st.features.push({ mesh: m, at: at, out: out }); }
    ["l", "r"].forEach(function (side) {
      var eye = idx(side + "_eyeball");
      feature(new T.SphereGeometry(0.017, 16, 12), white, [eye], -0.006);
      feature(new T.SphereGeometry(0.008, 12, 8), dark, [eye], 0.009);
    });
    feature(new T.SphereGeometry(0.016, 12, 10), nose, [idx("l_eyeball"), idx("r_eyeball"), idx("upper_lip"), idx("upper_lip")], 0.004);
    st.lines = [];
    /* A feature drawn as a line on the head from point a to point b, or (a brow) across the face through
       point a, reaching across on either side of it. */
    function line(a, b, r, mat, out, across) {
      var m = new T.Mesh(new T.CapsuleGeometry(r, 1, 3, 8), mat);
      s.scene.add(m);
      st.lines.push({ mesh: m, a: a, b: b, r: r, out: out, across: across || 0 });
    }
    st.eyes = [idx("l_eyeball"), idx("r_eyeball")];
    ["l", "r"].forEach(function (side) { line(idx(side + "_eyebrow.end"), idx(side + "_eyebrow.end"), 0.005, dark, 0.006, 0.017); });
    line(idx("upper_lip"), idx("upper_lip"), 0.006, lips, 0.008, 0.024);
    line(idx("lower_lip"), idx("lower_lip"), 0.006, lips, 0.008, 0.02);
    st.ambient = new T.HemisphereLight(0xffffff, 0x303030, 0.35);
    st.key = new T.DirectionalLight(0xffffff, 1.5);
    st.fill = new T.DirectionalLight(0xffffff, 0.3);
    st.back = new T.DirectionalLight(0xffffff, 1.2);
    [st.ambient, st.key, st.fill, st.back].forEach(function (l) { s.scene.add(l); if (l.target) s.scene.add(l.target); });
    st.centre = new T.Vector3(); st.tmp = new T.Vector3(); st.tmp2 = new T.Vector3();
    st.place = place; st.time = time; st.state = state;
    place(s, pts);
    time(s, 0, pts);
  }

  function at(pts, i, v) { return v.set(pts[i * 3], pts[i * 3 + 1], pts[i * 3 + 2]); }

  /* The point of the head's surface (plus out, m) in the direction of the mean of the points is. */
  function onHead(st, pts, is, out, v) {
    v.set(0, 0, 0);
    is.forEach(function (i) { v.x += pts[i * 3]; v.y += pts[i * 3 + 1]; v.z += pts[i * 3 + 2]; });
    v.multiplyScalar(1 / is.length).sub(st.centre);
    var n = v.length();
    if (n < 1e-6) v.set(0, 0, 1); else v.multiplyScalar(1 / n);
    return v.multiplyScalar(HEAD_R + out).add(st.centre);
  }

  function place(s, pts) {
    var st = s.stage, T = st.T, a = st.tmp, b = st.tmp2;
    st.segments.forEach(function (seg) {
      at(pts, seg.a, a); at(pts, seg.b, b);
      seg.mesh.position.copy(a).add(b).multiplyScalar(0.5);
      b.sub(a);
      var len = b.length();
      if (len > 1e-6) seg.mesh.quaternion.setFromUnitVectors(s.up, b.multiplyScalar(1 / len));
    });
    at(pts, st.base, a); at(pts, st.top, b);
    st.centre.copy(a).multiplyScalar(0.65).addScaledVector(b, 0.35);
    st.head.position.copy(st.centre);
    st.features.forEach(function (f) { onHead(st, pts, f.at, f.out, f.mesh.position); });
    st.lines.forEach(function (l) {
      onHead(st, pts, [l.a], l.out, a); onHead(st, pts, [l.b], l.out, b);
      if (l.across) {  // across the face: along the line from the right eye to the left
        var e = st.tmp3 || (st.tmp3 = new T.Vector3());
        at(pts, st.eyes[0], e); e.x -= pts[st.eyes[1] * 3]; e.y -= pts[st.eyes[1] * 3 + 1]; e.z -= pts[st.eyes[1] * 3 + 2];
        e.normalize().multiplyScalar(l.across);
        a.add(e); b.sub(e);
      }
      l.mesh.position.copy(a).add(b).multiplyScalar(0.5);
      b.sub(a);
      var len = b.length();
      if (len > 1e-6) l.mesh.quaternion.setFromUnitVectors(s.up, b.multiplyScalar(1 / len));
      l.mesh.scale.set(1, Math.max(len, 1e-4), 1);
    });
  }

  function rowAt(env, t) {
    var k = 0;
    for (var i = 0; i < env.rows.length; i++) if (env.rows[i].t <= t + 1e-9) k = i;
    return k;
  }

  /* Cut to the row of time t (camera and lights) when it is not the one shown. */
  function time(s, t, pts) {
    var st = s.stage, k = rowAt(st.env, t);
    if (k === st.row) return;
    st.row = k;
    var row = st.env.rows[k], T = st.T;
    var floor = Infinity;
    for (var i = 1; i < pts.length; i += 3) floor = Math.min(floor, pts[i]);
    var half = SHOTS[row.shot], y;
    if (row.shot === "full") y = floor + half - 0.08;
    else if (row.shot === "medium") y = st.centre.y + 0.1 - half;
    else if (row.shot === "close-up") y = st.centre.y - 0.02;
    else y = pts[st.base * 3 + 1] + 0.075;  // the eyes
    var target = new T.Vector3(st.centre.x, y, st.centre.z);
    var dist = half / Math.tan(FOV / 2 * Math.PI / 180) + (row.shot === "full" ? 0 : HEAD_R);
    var up = ANGLES[row.angle] * Math.PI / 180;
    s.camera.fov = FOV;
    // a low angle stays above the floor (steeper than the floor allows, it looks up less)
    s.camera.position.set(target.x, Math.max(target.y + dist * Math.sin(up), floor + 0.15), target.z + dist * Math.cos(up));
    s.camera.near = Math.max(0.01, dist / 20);
    s.camera.updateProjectionMatrix();
    s.camera.lookAt(target);
    if (s.controls) { s.controls.target.copy(target); s.controls.update(); }
    s.follow = [pts[0], pts[1], pts[2]];
    // three-point lighting: the key between the camera and the character (a little to its side and above), the
    // fill from the other side, the back light from behind and above
    var key = row.key, brightness = 1 - row.attenuation;
    st.key.color.setRGB(key[0] / 255, key[1] / 255, key[2] / 255);
    st.key.intensity = 3.0 * brightness;
    st.key.position.set(target.x + 0.35 * dist, target.y + 0.3 * dist, target.z + 0.5 * dist);
    st.fill.position.set(target.x - 0.8 * dist, target.y + 0.1 * dist, target.z + 0.6 * dist);
    st.back.position.set(target.x, target.y + dist, target.z - dist);
    [st.key, st.fill, st.back].forEach(function (l) { l.target.position.copy(target); l.target.updateMatrixWorld(); });
    st.target = target;
    s.dirty = true;
  }

  /* What the stage shows now: the row, the camera and the head's share of the frame. */
  function state(s) {
    var st = s.stage, row = st.env.rows[Math.max(st.row, 0)], c = s.camera.position;
    var d = c.distanceTo(st.centre), ry = HEAD_R / (d * Math.tan(s.camera.fov / 2 * Math.PI / 180));
    var eyes = st.features[0].mesh.position.y;
    return { row: st.row, t: row.t, emotion: row.emotion, intensity: row.intensity, shot: row.shot, angle: row.angle,
      key: [st.key.color.r, st.key.color.g, st.key.color.b], keyIntensity: st.key.intensity,
      attenuation: row.attenuation, valence: row.valence, music: row.music,
      camera: [c.x, c.y, c.z], target: [st.target.x, st.target.y, st.target.z], eyes: eyes,
      headShare: Math.min(1, Math.PI * ry * (ry / s.camera.aspect) / 4) };
  }

  window.REPORT_STAGE = { build: build };
})();
