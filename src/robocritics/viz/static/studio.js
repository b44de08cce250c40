/* The studio page: plain JS, no build step. Talks to the studio's JSON API (server.py); the 3-D replay is
   RoboReplay (replay.js). Every API call sends Content-Type: application/json, X-Studio: 1 and, when the page
   was opened with ?token=..., X-Studio-Token (docs/studio.md, security model). */
(function () {
  "use strict";
  const token = new URLSearchParams(location.search).get("token");
  const $ = (id) => document.getElementById(id);
  const headers = () => {
    const h = {"Content-Type": "application/json", "X-Studio": "1"};
    if (token) h["X-Studio-Token"] = token;
    return h;
  };
  const state = {critics: [], enabled: new Set(), revision: null, replay: null, busy: false, chat: null, deploy: null};

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

  function term(text, replace) {
    const t = $("terminal");
    t.textContent = replace ? text : t.textContent + text;
    t.scrollTop = t.scrollHeight;
  }

  // --- editor with line numbers and flagged lines ---------------------------------------------------
  let flagged = new Map();  // line -> "error" | "warning"
  function renderGutter() {
    const n = $("editor").value.split("\n").length;
    const g = $("gutter");
    const rows = [];
    for (let i = 1; i <= n; i++) {
      const f = flagged.get(i);
      rows.push(f ? `<div class="ln flagged" data-line="${i}" data-flag="${f}">${i}</div>` : `<div class="ln" data-line="${i}">${i}</div>`);
    }
    g.innerHTML = rows.join("");
    g.scrollTop = $("editor").scrollTop;
  }

  // --- critics panel ----------------------------------------------------------------------------------
  function renderCritics() {
    const box = $("critics");
    const verdicts = new Map(((state.revision && state.revision.verdicts) || []).map((v) => [v.critic, v]));
    box.innerHTML = "";
    for (const name of state.critics) {
      const v = verdicts.get(name);
      const row = document.createElement("div");
      row.className = "critic" + (state.enabled.has(name) ? "" : " off");
      row.dataset.critic = name;
      row.dataset.flag = v ? v.flag : "none";
      row.innerHTML = `<div class="head"><input type="checkbox" class="toggle" title="run this critic"><span class="name"></span>` +
        `<span class="flag"></span><button class="fix">Fix</button></div><div class="msg"></div><div class="hint"></div>`;
      row.querySelector(".toggle").checked = state.enabled.has(name);
      row.querySelector(".name").textContent = name;
      row.querySelector(".flag").textContent = v ? v.flag : "—";
      row.querySelector(".msg").textContent = v ? v.message : "";
      row.querySelector(".hint").textContent = v && v.hint ? "Hint: " + v.hint : "";
      const fix = row.querySelector(".fix");
      fix.disabled = !v || v.flag === "ok" || state.chat !== null || state.busy;
      fix.addEventListener("click", (e) => { e.stopPropagation(); runLLM("/api/fix", {critics: [name]}); });
      row.querySelector(".toggle").addEventListener("click", (e) => {
        e.stopPropagation();
        if (e.target.checked) state.enabled.add(name); else state.enabled.delete(name);
        row.classList.toggle("off", !e.target.checked);
      });
      row.addEventListener("click", () => { if (v && state.replay) state.replay.selectVerdict(name); });
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
      li.querySelector(".sc").textContent = score;
      li.addEventListener("click", async () => show(await api("/api/revision/" + r.index)));
      ol.appendChild(li);
    }
  }

  function updateButtons() {
    const r = state.revision;
    const failing = r && r.verdicts.some((v) => v.flag !== "ok");
    $("run").disabled = state.busy;
    $("fix-all").disabled = state.busy || state.chat !== null || !r || !(failing || r.error);
    $("deploy").disabled = state.busy || state.deploy !== null || !r || r.has_errors;
    $("deploy").title = state.deploy || (r && r.has_errors ? "disabled: the report has an Error" : "");
    $("fix-all").title = state.chat || "";
  }

  /* Show one revision: editor, critics, flagged lines, score, terminal, replay. */
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
    term(`# revision ${r.index} (${r.kind})` + (r.duration_s ? `, simulated in ${r.duration_s.toFixed(2)} s` : "") + "\n" + (r.feedback || "") + "\n", true);
    if (r.replay) state.replay.load(r.replay);
    renderCritics();
    api("/api/state").then((s) => renderHistory(s.revisions));
    updateButtons();
  }

  async function run() {
    state.busy = true; updateButtons();
    $("editor-status").textContent = "running…";
    document.body.dataset.running = "1";
    try {
      show(await api("/api/run", {program: $("editor").value, critics: state.critics.filter((c) => state.enabled.has(c))}));
      $("editor-status").textContent = "";
    } catch (e) {
      term("run failed: " + e.message + "\n", true);
      $("editor-status").textContent = "run failed";
    } finally {
      state.busy = false; delete document.body.dataset.running; updateButtons();
    }
  }

  // --- chat and Fix: an NDJSON stream of text / approval / revision events -------------------------------
  function chatMessage(role, text) {
    const div = document.createElement("div");
    div.className = "msg " + role;
    div.textContent = text;
    $("chat-log").appendChild(div);
    $("chat-log").scrollTop = $("chat-log").scrollHeight;
    return div;
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

  function askApproval(event) {
    renderDiff(event.diff || "(no change)");
    $("approval").hidden = false;
    $("approval").dataset.id = event.id;
  }
  async function answerApproval(ok) {
    const id = Number($("approval").dataset.id);
    $("approval").hidden = true;
    await api("/api/approve", {id, ok});
  }

  async function runLLM(path, body) {
    state.busy = true; updateButtons();
    const reply = chatMessage("assistant", "");
    reply.dataset.streaming = "1";
    if (path === "/api/fix") chatMessage("user", body.critics ? "Fix " + body.critics.join(", ") : "Fix all").before(reply);
    $("chat-status").textContent = "waiting for the model…";
    try {
      const index = state.revision ? state.revision.index : null;
      await stream(path, {...body, index, automation: $("automation").value}, (ev) => {
        if (ev.type === "text") { reply.textContent = ev.text; $("chat-status").textContent = "receiving…"; }
        else if (ev.type === "approval") askApproval(ev);
        else if (ev.type === "revision") show(ev.revision);
        else if (ev.type === "error") term("\n" + ev.error + "\n");
      });
    } catch (e) {
      term("\n" + e.message + "\n");
    } finally {
      delete reply.dataset.streaming;
      reply.dataset.done = "1";
      $("chat-status").textContent = "";
      state.busy = false; updateButtons(); renderCritics();
    }
  }

  // --- deploy ------------------------------------------------------------------------------------------
  function askDeploy() {
    const r = state.revision;
    $("deploy-text").textContent = `Revision ${r.index} (score ${r.score.toFixed(1)}) is re-planned from the arm's joints, ` +
      "checked by every critic and streamed to the controller only if the deploy gate passes. The robot will move.";
    $("deploy-dialog").hidden = false;
  }
  async function deploy() {
    $("deploy-dialog").hidden = true;
    state.busy = true; updateButtons();
    term("\n# deploying revision " + state.revision.index + " …\n");
    try {
      const result = await api("/api/deploy", {index: state.revision.index});
      term((result.ok ? "deployed: " : "") + result.message + "\n");
      document.body.dataset.deployed = result.ok ? "1" : "0";
    } catch (e) {
      term("deploy refused: " + e.message + "\n");
      document.body.dataset.deployed = "0";
    } finally { state.busy = false; updateButtons(); }
  }

  // --- start -------------------------------------------------------------------------------------------
  async function start() {
    const s = await api("/api/state");
    $("scene").textContent = "scene: " + s.scene;
    state.critics = s.critics;
    state.enabled = new Set(s.selected);
    state.chat = s.chat;
    state.deploy = s.deploy;
    $("editor").value = s.program;
    renderGutter();
    state.replay = RoboReplay.mount($("replay"), null, {verdictList: false});
    if (s.chat) {
      $("chat-status").textContent = "Chat is disabled: " + s.chat;
      $("chat-input").disabled = true; $("chat-send").disabled = true;
    }
    renderCritics();
    renderHistory(s.revisions);
    updateButtons();
    $("editor").addEventListener("input", renderGutter);
    $("editor").addEventListener("scroll", () => { $("gutter").scrollTop = $("editor").scrollTop; });
    $("run").addEventListener("click", run);
    $("fix-all").addEventListener("click", () => runLLM("/api/fix", {}));
    $("deploy").addEventListener("click", askDeploy);
    $("deploy-cancel").addEventListener("click", () => { $("deploy-dialog").hidden = true; });
    $("deploy-confirm").addEventListener("click", deploy);
    $("approve").addEventListener("click", () => answerApproval(true));
    $("reject").addEventListener("click", () => answerApproval(false));
    $("chat-form").addEventListener("submit", (e) => {
      e.preventDefault();
      const text = $("chat-input").value.trim();
      if (!text || state.busy) return;
      $("chat-input").value = "";
      chatMessage("user", text);
      runLLM("/api/chat", {text});
    });
    document.body.dataset.ready = "1";
  }
  start().catch((e) => { term("the studio could not start: " + e.message + "\n", true); });
})();
