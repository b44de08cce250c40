/* The studio page: plain JS, no build step. Talks to the studio's JSON API (server.py, handler.py); the 3-D
   replay is RoboReplay (replay.js). Every API call sends Content-Type: application/json and X-Studio: 1; the
   token, when the studio has one, is an HttpOnly cookie set by the first visit, which then drops it from the
   address bar (docs/studio.md, security model).

   The server runs one job at a time (run, fix, chat, repair, deploy). Every page polls GET /api/state, so what
   one tab started every tab shows: the job and its progress, a pending approval (also after a reload), the chat,
   the newest revision, the result of the last deploy. */
(function () {
  "use strict";
  const POLL_MS = 400;
  const url = new URL(location.href);
  const token = url.searchParams.get("token");
  if (token) { url.searchParams.delete("token"); history.replaceState(null, "", url.pathname + url.search + url.hash); }
  const $ = (id) => document.getElementById(id);
  const headers = () => {
    const h = {"Content-Type": "application/json", "X-Studio": "1"};
    if (token) h["X-Studio-Token"] = token;  // this first load only; the cookie carries it afterwards
    return h;
  };
  const state = {critics: [], enabled: new Set(), revision: null, replay: null, busy: false, chat: null,
    deploy: null, motion: null, server: null, known: 0, deployShown: null, chatVersion: -1, live: null, approvalId: null};

  async function api(path, body) {
    const init = body === undefined ? {headers: headers()} : {method: "POST", headers: headers(), body: JSON.stringify(body)};
    const r = await fetch(path, init);
    const data = await r.json();
    if (!r.ok) throw new Error(data.error || ("HTTP " + r.status));
    return data;
  }

  /* POST and read an NDJSON stream, calling onEvent for each line as it arrives. */
  async function stream(path, body, onEvent) {
    const r = await fetch(path, {method: "POST", headers: headers(), body: JSON.stringify(body)});
    if (!r.ok) { const d = await r.json(); throw new Error(d.error || ("HTTP " + r.status)); }
    const reader = r.body.getReader();
    const decoder = new TextDecoder();
    let buffer = "";
    for (;;) {
      const {value, done} = await reader.read();
      if (done) break;
      buffer += decoder.decode(value, {stream: true});
      let nl;
      while ((nl = buffer.indexOf("\n")) >= 0) {
        const line = buffer.slice(0, nl); buffer = buffer.slice(nl + 1);
        if (line.trim()) onEvent(JSON.parse(line));
      }
    }
  }

  /* The terminal: replace or append lines; Error lines red, Warning lines amber; scrolled to the first Error. */
  function term(text, replace) {
    const t = $("terminal");
    if (replace) t.textContent = "";
    let firstError = null;
    for (const line of text.split("\n")) {
      const span = document.createElement("span");
      span.textContent = line + "\n";
      if (/^Error\b/.test(line)) { span.className = "err"; if (!firstError) firstError = span; }
      else if (/^Warning\b/.test(line)) span.className = "warn";
      t.appendChild(span);
    }
    if (replace && firstError) { firstError.dataset.first = "1"; t.scrollTop = firstError.offsetTop - t.offsetTop - 4; }
    else if (!replace) t.scrollTop = t.scrollHeight;
  }

  /* One verdict as a terminal line: "Error [critic]: message. Hint: hint" (a message and its hint never run on). */
  function verdictLine(v) {
    const flag = v.flag === "error" ? "Error" : "Warning";
    const message = /[.!?)]$/.test(v.message.trim()) ? v.message.trim() : v.message.trim() + ".";
    const at = !v.lines.length && v.window ? ` (at ${v.window[0].toFixed(2)}-${v.window[1].toFixed(2)} s)` : "";
    return `${flag} [${v.critic}]${at}: ${message}` + (v.hint ? " Hint: " + v.hint : "");
  }

  // --- editor with line numbers and flagged lines ---------------------------------------------------
  let flagged = new Map();  // line -> "error" | "warning"
  function renderGutter() {
    const n = $("editor").value.split("\n").length;
    const rows = [];
    for (let i = 1; i <= n; i++) {
      const f = flagged.get(i);
      rows.push(f ? `<div class="ln flagged" data-line="${i}" data-flag="${f}">${i}</div>` : `<div class="ln" data-line="${i}">${i}</div>`);
    }
    $("gutter").innerHTML = rows.join("");
    $("gutter").scrollTop = $("editor").scrollTop;
  }

  const job = () => (state.server && state.server.job) || null;
  const editorDiffers = () => !!state.revision && $("editor").value !== state.revision.program;

  // --- critics panel ----------------------------------------------------------------------------------
  function fixBlocked(v) {
    const r = state.revision, j = job();
    if (state.motion) return "Fix disabled: " + state.motion.why;  // imported motion (docs/studio.md)
    if (!v || v.flag === "ok") return "nothing to fix";
    if (j) return "a " + j.kind + " is running";
    if (state.busy) return "busy";
    if (r && r.compact) return "this revision's run is no longer kept: Run it again";
    return "";
  }

  function renderCritics() {
    const box = $("critics");
    const r = state.revision;
    const verdicts = new Map(((r && r.verdicts) || []).map((v) => [v.critic, v]));
    const names = [...verdicts.keys()].filter((n) => !state.critics.includes(n)).concat(state.critics);
    const didNotRun = verdicts.has("runtime");
    box.innerHTML = "";
    for (const name of names) {
      const v = verdicts.get(name);
      const row = document.createElement("div");
      const extra = !state.critics.includes(name);
      row.className = "critic" + (extra || state.enabled.has(name) ? "" : " off");
      row.dataset.critic = name;
      row.dataset.flag = v ? v.flag : "none";
      row.innerHTML = `<div class="head"><input type="checkbox" class="toggle" title="score this critic"><span class="name"></span>` +
        `<span class="flag"></span><button class="fix">Fix</button></div><div class="msg"></div><div class="hint"></div>`;
      const toggle = row.querySelector(".toggle");
      toggle.checked = extra || state.enabled.has(name);
      toggle.hidden = extra;
      row.querySelector(".name").textContent = name;
      row.querySelector(".flag").textContent = v ? v.flag : "—";
      row.querySelector(".msg").textContent = v ? v.message : (didNotRun ? "not checked: the program did not run" : "");
      row.querySelector(".hint").textContent = v && v.hint ? "Hint: " + v.hint : "";
      const fix = row.querySelector(".fix");
      const why = fixBlocked(v);
      fix.disabled = !!why;
      fix.title = why || (state.chat ? "apply the critics' own repairs (no LLM is configured)" : "repairs first, then the model");
      fix.addEventListener("click", (e) => { e.stopPropagation(); runLLM("/api/fix", {critics: [name]}); });
      toggle.addEventListener("click", (e) => {
        e.stopPropagation();
        if (e.target.checked) state.enabled.add(name); else state.enabled.delete(name);
        row.classList.toggle("off", !e.target.checked);
      });
      row.addEventListener("click", () => { if (v && state.replay && r && r.replay) state.replay.selectVerdict(name); });
      box.appendChild(row);
    }
  }

  function renderHistory(revisions) {
    const ol = $("history");
    ol.innerHTML = "";
    for (const r of revisions) {
      const li = document.createElement("li");
      li.dataset.index = r.index;
      if (state.revision && state.revision.index === r.index) li.className = "current";
      const score = r.score === null ? "did not run" : "score " + r.score.toFixed(1);
      li.innerHTML = `<span class="kind"></span> <span class="sc"></span>`;
      li.querySelector(".kind").textContent = "#" + r.index + " " + r.kind;
      li.querySelector(".sc").textContent = score + (r.compact ? " · program only" : "");
      li.addEventListener("click", async () => show(await api("/api/revision/" + r.index)));
      ol.appendChild(li);
    }
    const current = ol.querySelector("li.current");
    if (current) current.scrollIntoView({block: "nearest"});
  }

  function deployBlocked() {
    const r = state.revision, j = job();
    if (state.deploy) return state.deploy;
    if (j && j.kind === "deploy") return "a deploy of " + j.detail + " is running";
    if (j) return "a " + j.kind + " is running";
    if (!r) return "Run the program first";
    if (editorDiffers()) return "the editor differs from revision " + r.index + ": Run it first";
    if (r.compact) return "revision " + r.index + "'s run is no longer kept: Run it again";
    if (r.blockers && r.blockers.length) return r.blockers.join(", ") + (r.blockers.length > 1 ? " report Errors" : " reports an Error");
    if (!r.deployable) return "revision " + r.index + " has no motion to deploy";
    return "";
  }

  function updateButtons() {
    const r = state.revision, j = job();
    const failing = r && r.verdicts.some((v) => v.flag !== "ok");
    const waiting = j && j.approval;
    $("run").disabled = state.busy || (!!j && !waiting);
    $("run").title = j && !waiting ? "a " + j.kind + " is running" : waiting ? "Run cancels the turn waiting for approval"
      : state.motion && state.motion.kind === "recording" ? "read and judge the recording again" : "";
    const fixWhy = state.motion ? fixBlocked(null) : !r ? "Run the program first" : !failing ? "every critic passed" : fixBlocked(r.verdicts.find((v) => v.flag !== "ok"));
    $("fix-all").disabled = !!fixWhy;
    $("fix-all").title = fixWhy || (state.chat ? "apply the critics' own repairs (no LLM is configured)" : "");
    const why = deployBlocked();
    $("deploy").disabled = !!why;
    $("deploy").title = why ? "Deploy disabled: " + why : "deploy revision " + r.index;
    $("deploy").dataset.why = why;
    const stoppable = j && (j.kind === "deploy" || j.kind === "fix" || j.kind === "chat" || j.kind === "repair");
    $("stop").hidden = !stoppable;
    $("deploy").hidden = !!(j && j.kind === "deploy");
    for (const b of document.querySelectorAll("#critics .fix")) {
      const v = r && r.verdicts.find((x) => x.critic === b.closest(".critic").dataset.critic);
      const blocked = fixBlocked(v);
      b.disabled = !!blocked;
      b.title = blocked || (state.chat ? "apply the critics' own repairs (no LLM is configured)" : "repairs first, then the model");
    }
    renderStatus();
  }

  function renderStatus() {
    const j = job();
    let text = "", fraction = 0;
    if (j) {
      const p = j.progress || {};
      if (j.kind === "deploy" && p.setpoints_total) {
        fraction = p.setpoints_sent / p.setpoints_total;
        text = `deploying ${j.detail}: ${p.setpoints_sent} / ${p.setpoints_total} setpoints · ` +
          `${p.time_s.toFixed(1)} / ${p.duration_s.toFixed(1)} s · tracking ${(p.tracking_error_rad * 1000).toFixed(1)} mrad ` +
          `(max ${(p.max_tracking_error_rad * 1000).toFixed(1)})` + (j.status && j.status !== "streaming" ? " · " + j.status : "");
      } else {
        text = `${j.kind}${j.detail ? " " + j.detail : ""}: ${j.status || "working"}… (${j.elapsed_s.toFixed(0)} s)`;
      }
      if (j.cancelling) text += " · stopping";
    } else if ($("deploy").dataset.why && state.revision && !state.deploy) {
      text = "Deploy disabled: " + $("deploy").dataset.why;
    }
    $("status-text").textContent = text;
    $("status").title = text;
    $("status-bar").style.width = (fraction * 100).toFixed(1) + "%";
    document.body.dataset.job = j ? j.kind : "";
    const turn = j && j.kind !== "deploy" && j.kind !== "run";
    $("chat-status").textContent = turn ? j.kind + ": " + (j.status || "working") + "…"
      : state.motion ? "Chat and Fix are disabled: " + state.motion.why + "."
      : state.chat ? "Chat is disabled: " + state.chat + ". Fix applies the critics' own repairs." : "";
  }

  /* Show one revision: editor, critics, flagged lines, score, terminal, replay (cleared when it has none). */
  function show(r) {
    state.revision = r;
    $("editor").value = r.program;
    flagged = new Map();
    for (const v of r.verdicts) {
      if (v.flag === "ok") continue;
      for (const line of v.lines) if (flagged.get(line) !== "error") flagged.set(line, v.flag);
    }
    renderGutter();
    const score = $("score");
    score.textContent = r.score === null ? "did not run" : "score " + r.score.toFixed(1) + " / 10";
    score.className = "st-score " + (r.has_errors ? "error" : r.verdicts.some((v) => v.flag === "warning") ? "warning" : "ok");
    score.dataset.score = r.score === null ? "" : String(r.score);
    const lines = r.verdicts.filter((v) => v.flag !== "ok").sort((a, b) => (a.flag === "error" ? 0 : 1) - (b.flag === "error" ? 0 : 1)).map(verdictLine);
    const body = lines.length ? lines.join("\n") : (r.feedback || "All selected critics passed.");
    term(`# revision ${r.index} (${r.kind})` + (r.duration_s ? `, simulated in ${r.duration_s.toFixed(2)} s` : "") + "\n" + body + "\n", true);
    state.replay.load(r.replay || null);
    $("replay-note").textContent = r.replay ? (state.motion ? "— " + state.motion.name : "") : r.compact ? "— not kept for old revisions: Run it again to replay" : "— no motion: the program did not run";
    renderCritics();
    if (state.server) renderHistory(state.server.revisions);
    updateButtons();
  }

  async function run() {
    state.busy = true; updateButtons();
    $("editor-status").textContent = "running…";
    document.body.dataset.running = "1";
    try {
      const r = await api("/api/run", {program: $("editor").value, critics: state.critics.filter((c) => state.enabled.has(c))});
      state.known = Math.max(state.known, r.index);
      show(r);
      await poll();  // the history lists the new revision before the page says the Run is done
      document.body.dataset.lastRun = String(r.index);
      $("editor-status").textContent = state.motionLabel || "";
    } catch (e) {
      term("run refused: " + e.message + "\n");
      $("editor-status").textContent = "run refused";
    } finally {
      state.busy = false; delete document.body.dataset.running; updateButtons();
    }
  }

  // --- chat, Fix and approvals ------------------------------------------------------------------------
  function renderChat(log) {
    if (!log) return;  // nothing said since the version this page has
    const box = $("chat-log");
    box.innerHTML = "";
    for (const m of log) {
      const div = document.createElement("div");
      div.className = "msg " + m.role;
      div.textContent = m.text;
      box.appendChild(div);
    }
    if (state.live) box.appendChild(state.live);
    box.scrollTop = box.scrollHeight;
  }

  /* A turn another page started (or this page before a reload): its reply so far, from the shared state. */
  function renderRemoteReply(text) {
    let div = $("chat-log").querySelector(".remote");
    if (!text) { if (div) div.remove(); return; }
    if (!div) { div = document.createElement("div"); div.className = "msg assistant live remote"; }
    div.textContent = text;
    if (div.parentNode !== $("chat-log") || div.nextSibling) { $("chat-log").appendChild(div); $("chat-log").scrollTop = $("chat-log").scrollHeight; }
  }

  function renderDiff(diff) {
    const pre = $("approval-diff");
    pre.innerHTML = "";
    for (const line of diff.split("\n")) {
      const span = document.createElement("div");
      span.className = line.startsWith("+") && !line.startsWith("+++") ? "add" : line.startsWith("-") && !line.startsWith("---") ? "del" : line.startsWith("@@") ? "hunk" : "";
      span.textContent = line || " ";
      pre.appendChild(span);
    }
  }

  function renderApproval(a) {
    const dialog = $("approval");
    if (!a) {
      if (!dialog.hidden) dialog.hidden = true;
      state.approvalId = null;
      return;
    }
    if (state.approvalId !== a.id) {
      state.approvalId = a.id;
      renderDiff(a.diff || "(no change)");
      $("approval-title").textContent = a.title;
      dialog.dataset.id = a.id;
      dialog.hidden = false;
    }
    $("approval-left").textContent = `Without an answer it counts as rejected in ${Math.ceil(a.seconds_left)} s.`;
  }

  async function answerApproval(ok) {
    const id = Number($("approval").dataset.id);
    $("approval").hidden = true;
    try { await api("/api/approve", {id, ok}); } catch (e) { term("\n" + e.message + "\n"); }
    poll();
  }

  async function runLLM(path, body) {
    state.busy = true; updateButtons();
    const live = document.createElement("div");
    live.className = "msg assistant live";
    live.dataset.streaming = "1";
    state.live = live;
    try {
      const index = state.revision ? state.revision.index : null;
      const selected = state.critics.filter((c) => state.enabled.has(c));
      await stream(path, {...body, index, selected, automation: $("automation").value}, (ev) => {
        if (ev.type === "text") {
          live.textContent = ev.text;
          if (ev.phase === "receiving") $("chat-status").textContent = "receiving the model's reply…";
          if (!live.parentNode) { $("chat-log").appendChild(live); }
          $("chat-log").scrollTop = $("chat-log").scrollHeight;
        } else if (ev.type === "revision") { state.known = Math.max(state.known, ev.revision.index); show(ev.revision); }
        else if (ev.type === "error") term("\n" + ev.error + "\n");
      });
    } catch (e) {
      term("\n" + e.message + "\n");
    } finally {
      state.live = null;
      live.remove();
      delete live.dataset.streaming;
      state.busy = false;
      state.chatVersion = -1;  // draw the chat again (the live reply is gone; the server's log has it)
      await poll();
      const last = [...document.querySelectorAll("#chat-log .msg")].pop();
      if (last) last.dataset.done = "1";
      document.body.dataset.turns = String(Number(document.body.dataset.turns || 0) + 1);
    }
  }

  // --- deploy ------------------------------------------------------------------------------------------
  function askDeploy() {
    const r = state.revision;
    $("deploy-text").textContent = `Revision ${r.index} (score ${r.score.toFixed(1)}): exactly the motion shown in the ` +
      "replay is checked by the deploy gate and streamed to the controller. The robot will move; ■ Stop (on every open page) stops it.";
    $("deploy-dialog").hidden = false;
  }
  async function deploy() {
    $("deploy-dialog").hidden = true;
    const index = state.revision.index;
    try {
      const result = await api("/api/deploy", {index, program: $("editor").value});
      term("\n# " + result.message + " …\n");
    } catch (e) {
      term("\ndeploy refused: " + e.message + "\n");
      document.body.dataset.refused = e.message;
    }
    poll();
  }
  function showDeployResult(d) {
    if (!d || d.job === state.deployShown) return;
    state.deployShown = d.job;
    const head = d.ok ? "" : d.cause === "stop_requested" ? "stopped by Stop: " : "";
    term("\n" + head + d.message + (d.stop_latency_s !== undefined ? ` (arm stopped ${d.stop_latency_s.toFixed(2)} s after Stop)` : "") + "\n");
    document.body.dataset.deployed = d.ok ? "1" : "0";
  }

  // --- the shared state, polled ------------------------------------------------------------------------
  async function poll() {
    let s;
    try { s = await api("/api/state?chat=" + state.chatVersion); } catch (e) { $("status-text").textContent = "studio unreachable: " + e.message; return; }
    state.server = s;
    const j = s.job;
    renderApproval(j && j.approval);
    renderChat(s.chat_log);
    state.chatVersion = s.chat_version;
    renderRemoteReply(j && !state.live ? j.reply : "");
    showDeployResult(s.last_deploy);
    if (s.revisions.length > state.known && !state.busy) {
      state.known = s.revisions.length;
      show(await api("/api/revision/latest"));
    } else {
      renderHistory(s.revisions);
      updateButtons();
    }
  }

  async function loop() {
    for (;;) {
      await poll();
      await new Promise((resolve) => setTimeout(resolve, POLL_MS));
    }
  }

  // --- start -------------------------------------------------------------------------------------------
  async function start() {
    const s = await api("/api/state");
    $("scene").textContent = "scene: " + s.scene;
    state.critics = s.critics;
    state.enabled = new Set(s.selected);
    state.chat = s.chat;
    state.deploy = s.deploy;
    state.motion = s.motion;  // a URScript file or a recording, not a program (Fix, chat and Deploy off)
    if (s.motion) {
      $("editor").readOnly = s.motion.kind === "recording";
      state.motionLabel = s.motion.kind === "recording" ? s.motion.name + " (recording, read-only)" : s.motion.name + " (URScript)";
      $("editor-status").textContent = state.motionLabel;
      $("chat-input").title = s.motion.why;
    }
    state.server = s;
    state.deployShown = s.last_deploy ? s.last_deploy.job : null;
    $("editor").value = s.program;
    renderGutter();
    state.replay = RoboReplay.mount($("replay"), null, {verdictList: false});
    if (s.chat) { $("chat-input").disabled = true; $("chat-send").disabled = true; }
    renderCritics();
    renderHistory(s.revisions);
    if (s.last_deploy) { state.deployShown = null; showDeployResult(s.last_deploy); }
    if (s.revisions.length) { state.known = s.revisions.length; show(await api("/api/revision/latest")); }
    updateButtons();
    $("editor").addEventListener("input", () => { renderGutter(); updateButtons(); });
    $("editor").addEventListener("scroll", () => { $("gutter").scrollTop = $("editor").scrollTop; });
    $("run").addEventListener("click", run);
    $("fix-all").addEventListener("click", () => runLLM("/api/fix", {}));
    $("deploy").addEventListener("click", askDeploy);
    $("stop").addEventListener("click", async () => {
      try { const r = await api("/api/stop", {}); term("\n# " + r.message + "\n"); } catch (e) { term("\n" + e.message + "\n"); }
      poll();
    });
    $("deploy-cancel").addEventListener("click", () => { $("deploy-dialog").hidden = true; });
    $("deploy-confirm").addEventListener("click", deploy);
    $("approve").addEventListener("click", () => answerApproval(true));
    $("reject").addEventListener("click", () => answerApproval(false));
    $("chat-form").addEventListener("submit", (e) => {
      e.preventDefault();
      const text = $("chat-input").value.trim();
      if (!text || state.busy) return;
      $("chat-input").value = "";
      runLLM("/api/chat", {text});
    });
    document.body.dataset.ready = "1";
    loop();
  }
  start().catch((e) => { term("the studio could not start: " + e.message + "\n", true); });
})();
