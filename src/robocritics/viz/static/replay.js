/* robocritics 3-D replay: draws the data of robocritics.viz.replay_data() with three.js (global THREE).
 *
 * RoboReplay.mount(element, data, {verdictList}) -> replay
 *   replay.load(data) | play() | pause() | seek(t_s) | setSpeed(x) | setLoop(bool) | selectVerdict(critic)
 *   replay.time, replay.duration (s); replay.onTime(cb), replay.onSelect(cb)
 * Coordinates are the robot base frame (m, z up). Times are seconds on the physical time axis.
 */
(function (global) {
  "use strict";
  const FORMAT = "robocritics-replay/1";
  const SPEEDS = [0.25, 0.5, 1, 2, 4];
  const FLAG_ORDER = { ERROR: 0, WARNING: 1, OK: 2 };
  const HIGHLIGHT = { ERROR: 0xd33a2c, WARNING: 0xe0a100, OK: 0x2e9d4a };

  function decode(blob) {
    // {dtype: "float32", shape, data: base64 little-endian}
    const bytes = Uint8Array.from(atob(blob.data), (c) => c.charCodeAt(0));
    return { values: new Float32Array(bytes.buffer), shape: blob.shape };
  }

  function el(tag, cls, parent, text) {
    const node = document.createElement(tag);
    if (cls) node.className = cls;
    if (text !== undefined) node.textContent = text;
    if (parent) parent.appendChild(node);
    return node;
  }

  function fmtTime(t) {
    return t.toFixed(2) + " s";
  }

  // Matrix4 from the row-major top 3x4 of a pose.
  function setPose(object, m, offset) {
    const o = offset || 0;
    object.matrix.set(m[o], m[o + 1], m[o + 2], m[o + 3], m[o + 4], m[o + 5], m[o + 6], m[o + 7],
      m[o + 8], m[o + 9], m[o + 10], m[o + 11], 0, 0, 0, 1);
    object.matrixWorldNeedsUpdate = true;
  }

  function material(colour, opts) {
    return new THREE.MeshStandardMaterial(Object.assign({ color: colour, roughness: 0.6, metalness: 0.1 }, opts || {}));
  }

  function objectGeometry(o) {
    if (o.shape === "mesh" && o.triangles) {
      // a fixture from CAD: its triangles (m, its own frame; decimated to a bound by replay_data)
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(decode(o.triangles).values, 3));
      g.computeVertexNormals();
      return g;
    }
    if (o.shape === "box" || o.shape === "mesh") return new THREE.BoxGeometry(o.size[0], o.size[1], o.size[2]);
    if (o.shape === "sphere") return new THREE.SphereGeometry(o.size[0], 24, 16);
    // cylinder: three.js cylinders run along y; ours along z
    const g = new THREE.CylinderGeometry(o.size[0], o.size[0], o.size[1], 28);
    g.rotateX(Math.PI / 2);
    return g;
  }

  // A small orbit camera: drag to rotate about the target, shift/right-drag to pan, wheel to zoom.
  function OrbitCamera(camera, dom, onChange) {
    const state = { azimuth: -0.9, elevation: 0.55, distance: 1.35, target: new THREE.Vector3(0.15, 0, 0.12) };
    function apply() {
      const c = Math.cos(state.elevation);
      camera.position.set(
        state.target.x + state.distance * c * Math.cos(state.azimuth),
        state.target.y + state.distance * c * Math.sin(state.azimuth),
        state.target.z + state.distance * Math.sin(state.elevation));
      camera.up.set(0, 0, 1);
      camera.lookAt(state.target);
      onChange();
    }
    let drag = null;
    dom.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
      dom.setPointerCapture(e.pointerId);
    });
    dom.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) {
        const right = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 0);
        const up = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 1);
        const k = state.distance * 0.0015;
        state.target.addScaledVector(right, -dx * k).addScaledVector(up, dy * k);
      } else {
        state.azimuth -= dx * 0.008;
        state.elevation = Math.max(-0.2, Math.min(1.5, state.elevation + dy * 0.008));
      }
      apply();
    });
    dom.addEventListener("pointerup", () => { drag = null; });
    dom.addEventListener("contextmenu", (e) => e.preventDefault());
    dom.addEventListener("wheel", (e) => {
      e.preventDefault();
      state.distance = Math.max(0.3, Math.min(6, state.distance * Math.exp(e.deltaY * 0.001)));
      apply();
    }, { passive: false });
    this.state = state;
    this.apply = apply;
  }

  function Replay(element, options) {
    this.element = element;
    this.options = Object.assign({ verdictList: true }, options || {});
    this.timeListeners = [];
    this.selectListeners = [];
    this.speed = 1;
    this.loop = false;
    this.playing = false;
    this.t = 0;
    this.data = null;
    this.selected = null;
    this._build();
  }

  Replay.prototype._build = function () {
    const root = this.element;
    root.classList.add("rc-replay");
    root.innerHTML = "";
    const stage = el("div", "rc-stage", root);
    this.canvas = el("canvas", "rc-canvas", stage);
    this.caption = el("div", "rc-caption", stage);
    this.empty = el("div", "rc-empty", stage, "No motion yet: run a program to see it here.");

    const controls = el("div", "rc-controls", root);
    this.playButton = el("button", "rc-play", controls, "▶");
    this.playButton.type = "button";
    this.playButton.title = "Play / pause (space)";
    this.scrub = el("input", "rc-scrub", controls);
    Object.assign(this.scrub, { type: "range", min: 0, max: 1000, step: 1, value: 0 });
    this.scrub.title = "Scrub the time axis";
    this.timeLabel = el("span", "rc-time", controls, "0.00 s");
    const speedLabel = el("label", "rc-speed-label", controls, "speed ");
    this.speedSelect = el("select", "rc-speed", speedLabel);
    SPEEDS.forEach((s) => {
      const opt = el("option", "", this.speedSelect, s + "×");
      opt.value = String(s);
      if (s === 1) opt.selected = true;
    });
    const loopLabel = el("label", "rc-loop-label", controls);
    this.loopBox = el("input", "rc-loop", loopLabel);
    this.loopBox.type = "checkbox";
    loopLabel.appendChild(document.createTextNode(" loop"));

    this.timeline = el("div", "rc-timeline", root);
    this.verdictList = this.options.verdictList ? el("div", "rc-verdicts", root) : null;

    this.playButton.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
    this.scrub.addEventListener("input", () => {
      this.pause();
      this.seek((this.scrub.value / 1000) * this.duration);
    });
    this.speedSelect.addEventListener("change", () => this.setSpeed(parseFloat(this.speedSelect.value)));
    this.loopBox.addEventListener("change", () => this.setLoop(this.loopBox.checked));
    root.tabIndex = 0;
    root.addEventListener("keydown", (e) => {
      if (e.target !== root && e.target !== this.canvas) return;
      if (e.key === " ") { e.preventDefault(); this.playing ? this.pause() : this.play(); }
      if (e.key === "ArrowRight") this.seek(this.t + 0.1);
      if (e.key === "ArrowLeft") this.seek(this.t - 0.1);
    });

    this.renderer = new THREE.WebGLRenderer({ canvas: this.canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(global.devicePixelRatio || 1, 2));
    this.scene3 = new THREE.Scene();
    this.scene3.background = new THREE.Color(0xeef1f5);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 50);
    this.scene3.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1.5, -1.0, 2.5);
    this.scene3.add(sun);
    this.orbit = new OrbitCamera(this.camera, this.canvas, () => this._requestRender());
    this.world = new THREE.Group();
    this.scene3.add(this.world);
    this._resize();
    if (global.ResizeObserver) new ResizeObserver(() => this._resize()).observe(stage);
    this.orbit.apply();
  };

  Replay.prototype._resize = function () {
    const stage = this.canvas.parentElement;
    const w = Math.max(200, stage.clientWidth), h = Math.max(160, stage.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this._requestRender();
  };

  Replay.prototype._requestRender = function () {
    if (this._renderQueued) return;
    this._renderQueued = true;
    requestAnimationFrame(() => {
      this._renderQueued = false;
      this.renderer.render(this.scene3, this.camera);
      if (this.data) this.element.dataset.ready = "1";
    });
  };

  Replay.prototype.load = function (data) {
    this.pause();
    this.world.clear();
    this.data = null;
    this.selected = null;
    this.t = 0;
    this.timeline.innerHTML = "";
    if (this.verdictList) this.verdictList.innerHTML = "";
    this.empty.style.display = data ? "none" : "";
    delete this.element.dataset.ready;
    if (!data) {
      this.duration = 0;
      this.caption.textContent = "";
      this._requestRender();
      return;
    }
    if (data.format !== FORMAT) throw new Error("replay data format " + data.format + " is not " + FORMAT);
    this.data = data;
    this.times = decode(data.time_s).values;
    this.ends = decode(data.capsule_ends).values; // (F, C, 6)
    this.nCapsules = data.capsules.length;
    this.duration = data.duration_s;
    this._frameCamera(data.workspace, data.humans || []);
    this._buildScene(data);
    this._buildTimeline(data);
    this._buildVerdictList(data);
    this.seek(0);
  };

  // Frame the robot's allowed workspace (its reach sphere): the same view on a UR3e as on a UR16e.
  Replay.prototype._frameCamera = function (ws, humans) {
    const r = ws.radius_m, st = this.orbit.state;
    st.target.set(ws.center[0] + 0.3 * r, ws.center[1], 0.24 * r);
    st.distance = 2.7 * r;
    if (humans.length) {
      // people in the cell: aim between the workspace and them, far enough back to see them whole
      const box = new THREE.Box3(new THREE.Vector3(ws.center[0] - r, ws.center[1] - r, 0),
        new THREE.Vector3(ws.center[0] + r, ws.center[1] + r, ws.center[2] + r));
      for (const h of humans) for (const c of h.capsules) {
        for (const p of [c.p0, c.p1]) box.expandByPoint(new THREE.Vector3(p[0], p[1], p[2]));
      }
      box.getCenter(st.target);
      st.distance = Math.max(st.distance, 1.3 * box.getSize(new THREE.Vector3()).length());
    }
    this.orbit.apply();
  };

  Replay.prototype._buildScene = function (data) {
    const world = this.world;
    this.boxMeshes = [];
    for (const b of data.boxes) {
      const mesh = new THREE.Mesh(new THREE.BoxGeometry(b.size[0], b.size[1], b.size[2]),
        material(b.colour, b.kind === "table" ? { roughness: 0.9 } : {}));
      mesh.matrixAutoUpdate = false;
      setPose(mesh, b.pose);
      mesh.userData = { owner: b.owner, base: new THREE.Color(b.colour) };
      world.add(mesh);
      this.boxMeshes.push(mesh);
    }
    const table = data.boxes.find((b) => b.kind === "table");
    if (table) {
      const topZ = table.pose[11] + table.size[2] / 2 + 0.0005;
      const grid = new THREE.GridHelper(Math.max(table.size[0], table.size[1]), 16, 0xb9ad98, 0xcbbfa9);
      grid.rotation.x = Math.PI / 2;
      grid.position.set(table.pose[3], table.pose[7], topZ);
      world.add(grid);
    }
    const ws = data.workspace;
    const sphere = new THREE.Mesh(new THREE.SphereGeometry(ws.radius_m, 36, 18),
      new THREE.MeshBasicMaterial({ color: 0x5c8fd6, wireframe: true, transparent: true, opacity: 0.05 }));
    sphere.position.set(ws.center[0], ws.center[1], ws.center[2]);
    world.add(sphere);

    this.objectMeshes = {};
    this.movingObjects = [];
    for (const o of data.objects) {
      const mesh = new THREE.Mesh(objectGeometry(o), material(o.colour));
      mesh.matrixAutoUpdate = false;
      setPose(mesh, o.pose);
      mesh.userData = { owner: o.id, base: new THREE.Color(o.colour) };
      world.add(mesh);
      this.objectMeshes[o.id] = mesh;
      if (o.poses) this.movingObjects.push({ mesh: mesh, poses: decode(o.poses).values });
    }

    // people: the capsules of their ISO/TS 15066 body regions (static)
    this.humanMeshes = [];
    for (const h of data.humans || []) {
      for (const c of h.capsules) {
        const a = new THREE.Vector3(c.p0[0], c.p0[1], c.p0[2]), b = new THREE.Vector3(c.p1[0], c.p1[1], c.p1[2]);
        const axis = b.clone().sub(a);
        const colour = c.region === "skull_forehead" || c.region === "face" ? "#d9a066" : "#e7b98a";
        const mesh = new THREE.Mesh(new THREE.CapsuleGeometry(c.radius_m, axis.length(), 6, 18),
          material(colour, { roughness: 0.8 }));
        mesh.position.copy(a.clone().add(b).multiplyScalar(0.5));
        if (axis.lengthSq() > 1e-12) mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), axis.normalize());
        mesh.userData = { owner: c.name, person: h.id, base: new THREE.Color(colour) };
        world.add(mesh);
        this.humanMeshes.push(mesh);
      }
    }
    this.element.dataset.people = String((data.humans || []).length);
    // mesh fixtures drawn from their triangles (a test reads it, as it reads the people)
    this.element.dataset.meshes = String(data.objects.filter((o) => o.shape === "mesh" && o.triangles).length);

    this.capsuleMeshes = [];
    const first = this.ends;
    data.capsules.forEach((c, i) => {
      const dx = first[i * 6 + 3] - first[i * 6], dy = first[i * 6 + 4] - first[i * 6 + 1], dz = first[i * 6 + 5] - first[i * 6 + 2];
      const length = Math.hypot(dx, dy, dz);
      const colour = c.group === "gripper" ? "#3d4550" : "#aeb8c4";
      const mesh = new THREE.Mesh(new THREE.CapsuleGeometry(c.radius_m, length, 6, 18),
        material(colour, { metalness: 0.25, roughness: 0.45 }));
      mesh.userData = { owner: c.name, base: new THREE.Color(colour) };
      world.add(mesh);
      this.capsuleMeshes.push(mesh);
    });

    this.segment = new THREE.Group();
    this.segment.visible = false;
    world.add(this.segment);
  };

  Replay.prototype._frameAt = function (t) {
    // last frame whose time <= t (binary search)
    const times = this.times;
    let lo = 0, hi = times.length - 1;
    if (t <= times[0]) return 0;
    if (t >= times[hi]) return hi;
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (times[mid] <= t) lo = mid; else hi = mid;
    }
    return lo;
  };

  const Y_AXIS = new THREE.Vector3(0, 1, 0);
  Replay.prototype._drawFrame = function (f) {
    const C = this.nCapsules, ends = this.ends, base = f * C * 6;
    const axis = new THREE.Vector3();
    for (let i = 0; i < C; i++) {
      const o = base + i * 6;
      const mesh = this.capsuleMeshes[i];
      mesh.position.set((ends[o] + ends[o + 3]) / 2, (ends[o + 1] + ends[o + 4]) / 2, (ends[o + 2] + ends[o + 5]) / 2);
      axis.set(ends[o + 3] - ends[o], ends[o + 4] - ends[o + 1], ends[o + 5] - ends[o + 2]);
      if (axis.lengthSq() > 1e-12) mesh.quaternion.setFromUnitVectors(Y_AXIS, axis.normalize());
    }
    for (const m of this.movingObjects) setPose(m.mesh, m.poses, f * 12);
    const step = this.data.steps[this.data.step[f]];
    const carrying = this.data.attached[f] >= 0 ? " · carrying " + this.data.attached_ids[this.data.attached[f]] : "";
    this.caption.textContent = step ? "line " + step.line + ": " + (step.args || step.skill + "()") + carrying : "";
    this.frame = f;
  };

  Replay.prototype.seek = function (t) {
    if (!this.data) return;
    this.t = Math.max(0, Math.min(this.duration, t));
    this._drawFrame(this._frameAt(this.t));
    this.scrub.value = String(this.duration > 0 ? Math.round((this.t / this.duration) * 1000) : 0);
    this.timeLabel.textContent = fmtTime(this.t) + " / " + fmtTime(this.duration);
    // the tracks start after the 10 px padding and 130 px labels and end 10 px before the right edge
    if (this.cursor) this.cursor.style.left = "calc(140px + (100% - 150px) * " + (this._pct(this.t) / 100) + ")";
    this.element.dataset.time = this.t.toFixed(3);
    this._requestRender();
    for (const cb of this.timeListeners) cb(this.t);
  };

  Replay.prototype.play = function () {
    if (!this.data || this.playing) return;
    if (this.t >= this.duration) this.seek(0);
    this.playing = true;
    this.playButton.textContent = "❚❚";
    this.element.dataset.playing = "1";
    let last = performance.now();
    const tick = (now) => {
      if (!this.playing) return;
      const dt = Math.min(0.25, (now - last) / 1000);
      last = now;
      let t = this.t + dt * this.speed;
      if (t >= this.duration) {
        if (this.loop) t = 0; else { this.seek(this.duration); this.pause(); return; }
      }
      this.seek(t);
      requestAnimationFrame(tick);
    };
    requestAnimationFrame(tick);
  };

  Replay.prototype.pause = function () {
    this.playing = false;
    if (this.playButton) this.playButton.textContent = "▶";
    delete this.element.dataset.playing;
  };

  Replay.prototype.setSpeed = function (x) {
    this.speed = Math.max(0.25, Math.min(4, Number(x) || 1));
    this.speedSelect.value = String(this.speed);
  };

  Replay.prototype.setLoop = function (on) {
    this.loop = Boolean(on);
    this.loopBox.checked = this.loop;
  };

  Replay.prototype._pct = function (t) {
    return this.duration > 0 ? (100 * t) / this.duration : 0;
  };

  Replay.prototype._buildTimeline = function (data) {
    const tl = this.timeline;
    const rows = data.verdicts.slice().sort((a, b) => FLAG_ORDER[a.flag] - FLAG_ORDER[b.flag]);
    for (const v of rows) {
      const row = el("div", "rc-row", tl);
      row.dataset.critic = v.critic;
      const label = el("span", "rc-row-label", row, v.critic);
      label.style.color = v.colour;
      const track = el("div", "rc-track", row);
      for (const w of v.windows_s) {
        const mark = el("div", "rc-mark", track);
        mark.dataset.critic = v.critic;
        mark.dataset.flag = v.flag;
        mark.style.left = this._pct(w[0]) + "%";
        mark.style.width = Math.max(0.4, this._pct(w[1]) - this._pct(w[0])) + "%";
        mark.style.background = v.colour;
        mark.title = v.critic + " " + v.flag + ": " + fmtTime(w[0]) + " – " + fmtTime(w[1]);
        mark.addEventListener("click", (e) => { e.stopPropagation(); this.selectVerdict(v.critic); });
      }
      track.addEventListener("click", (e) => {
        const r = track.getBoundingClientRect();
        this.pause();
        this.seek(((e.clientX - r.left) / r.width) * this.duration);
      });
    }
    if (!rows.length) {
      const row = el("div", "rc-row", tl);
      el("span", "rc-row-label", row, "time");
      const track = el("div", "rc-track", row);
      track.addEventListener("click", (e) => {
        const r = track.getBoundingClientRect();
        this.seek(((e.clientX - r.left) / r.width) * this.duration);
      });
    }
    this.cursor = el("div", "rc-cursor", tl);
  };

  Replay.prototype._buildVerdictList = function (data) {
    if (!this.verdictList) return;
    if (data.score_text) el("div", "rc-score", this.verdictList, data.score_text);
    const rows = data.verdicts.slice().sort((a, b) => FLAG_ORDER[a.flag] - FLAG_ORDER[b.flag]);
    for (const v of rows) {
      const row = el("div", "rc-verdict", this.verdictList);
      row.dataset.critic = v.critic;
      row.dataset.flag = v.flag;
      const head = el("div", "rc-verdict-head", row);
      const badge = el("span", "rc-badge", head, v.flag);
      badge.style.background = v.colour;
      el("b", "", head, " " + v.critic);
      el("div", "rc-message", row, v.message);
      if (v.hint) el("div", "rc-hint", row, v.hint);
      row.addEventListener("click", () => this.selectVerdict(v.critic));
    }
  };

  Replay.prototype.selectVerdict = function (critic) {
    if (!this.data) return;
    const v = this.data.verdicts.find((x) => x.critic === critic);
    if (!v) return;
    this.selected = critic;
    const involved = new Set((v.links || []).concat(v.objects || []));
    const colour = new THREE.Color(HIGHLIGHT[v.flag]);
    const meshes = this.capsuleMeshes.concat(this.boxMeshes, Object.values(this.objectMeshes), this.humanMeshes);
    for (const m of meshes) {
      const on = v.flag !== "OK" && (involved.has(m.userData.owner) || involved.has(m.userData.person));
      m.material.emissive = on ? colour : new THREE.Color(0x000000);
      m.material.emissiveIntensity = on ? 0.55 : 0;
    }
    this.segment.clear();
    this.segment.visible = false;
    if (v.segment && v.flag !== "OK") {
      const [a, b] = v.segment.map((p) => new THREE.Vector3(p[0], p[1], p[2]));
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints([a, b]),
        new THREE.LineBasicMaterial({ color: HIGHLIGHT[v.flag], depthTest: false }));
      line.renderOrder = 10;
      this.segment.add(line);
      for (const p of [a, b]) {
        const dot = new THREE.Mesh(new THREE.SphereGeometry(0.006, 12, 8),
          new THREE.MeshBasicMaterial({ color: HIGHLIGHT[v.flag], depthTest: false }));
        dot.position.copy(p);
        dot.renderOrder = 11;
        this.segment.add(dot);
      }
      this.segment.visible = true;
    }
    if (this.verdictList) {
      for (const row of this.verdictList.querySelectorAll(".rc-verdict")) {
        row.classList.toggle("rc-selected", row.dataset.critic === critic);
      }
    }
    for (const row of this.timeline.querySelectorAll(".rc-row")) {
      row.classList.toggle("rc-selected", row.dataset.critic === critic);
    }
    this.element.dataset.selected = critic;
    this.pause();
    if (v.worst_time_s !== null && v.worst_time_s !== undefined) this.seek(v.worst_time_s);
    else this._requestRender();
    for (const cb of this.selectListeners) cb(critic);
  };

  Replay.prototype.onTime = function (cb) { this.timeListeners.push(cb); };
  Replay.prototype.onSelect = function (cb) { this.selectListeners.push(cb); };
  Object.defineProperty(Replay.prototype, "time", { get: function () { return this.t; } });

  global.RoboReplay = {
    FORMAT: FORMAT,
    mount: function (element, data, options) {
      const replay = new Replay(element, options);
      replay.load(data || null);
      return replay;
    },
  };
})(typeof window !== "undefined" ? window : this);
