/* Sequences page: drag-and-drop upload with progress, the list, starting jobs and batches. */
"use strict";
(() => {
  const { api, el, showError, toast, num, bytes, seconds, when, statusBadge } = VTD;
  const $ = (id) => document.getElementById(id);
  const fileInput = $("file"), zone = $("dropzone"), uploadBtn = $("upload-btn");
  let chosen = null;

  // ---- choosing a file ----
  function choose(file) {
    chosen = file || null;
    const label = $("file-chosen");
    label.hidden = !chosen;
    label.textContent = chosen ? `${chosen.name} · ${bytes(chosen.size)}` : "";
    uploadBtn.disabled = !chosen;
    showError($("upload-error"), null);
    if (chosen && !/\.(zip|tgz|tar\.gz|tar|bag|mcap|db3)$/i.test(chosen.name)) {
      showError($("upload-error"), new Error(`"${chosen.name}" is not a .zip, .tar.gz or .tgz archive nor a ROS bag (.bag, .mcap, .db3); the server will likely refuse it`));
    }
  }
  fileInput.addEventListener("change", () => choose(fileInput.files[0]));
  for (const ev of ["dragenter", "dragover"]) zone.addEventListener(ev, (e) => { e.preventDefault(); zone.classList.add("over"); });
  for (const ev of ["dragleave", "drop"]) zone.addEventListener(ev, () => zone.classList.remove("over"));
  zone.addEventListener("drop", (e) => {
    e.preventDefault();
    const files = e.dataTransfer && e.dataTransfer.files;
    if (files && files.length) choose(files[0]);
  });
  $("camera").addEventListener("change", () => { $("intr-wrap").hidden = $("camera").value !== "custom"; });

  // ---- uploading (XHR: fetch has no upload progress) ----
  $("upload-form").addEventListener("submit", (e) => {
    e.preventDefault();
    if (!chosen) return;
    let camera = $("camera").value;
    if (camera === "custom") {
      camera = $("intrinsics").value.trim();
      try { JSON.parse(camera); } catch (err) {
        showError($("upload-error"), new Error("The intrinsics are not valid JSON: " + err.message)); return;
      }
    }
    upload(uploadForm(camera, false), chosen.size);
  });

  function uploadForm(camera, allowDuplicate) {
    const form = new FormData();
    form.append("camera", camera);
    const name = $("seq-name").value.trim();
    if (name) form.append("name", name);
    if (allowDuplicate) form.append("allow_duplicate", "true");
    form.append("file", chosen, chosen.name); // last: the server reads the fields first
    return form;
  }

  /** The api's 409 for an archive uploaded before: name the sequence, offer to add it again anyway. */
  function duplicateRefused(err, camera) {
    showError($("upload-error"), err, "Not added");
    const again = el("button", { type: "button", class: "small", id: "upload-anyway", onclick: () => {
      if (chosen) upload(uploadForm(camera, true), chosen.size);
    } }, "Upload it again anyway");
    $("upload-error").append(el("div", { class: "actions" }, again));
  }

  function upload(form, total, retried = false) {
    const bar = $("upload-bar"), text = $("upload-text"), errBox = $("upload-error"), cancel = $("upload-cancel");
    showError(errBox, null);
    $("upload-note").hidden = true;
    $("upload-progress").hidden = false;
    uploadBtn.disabled = true;
    cancel.hidden = false;
    bar.value = 0;
    text.textContent = "starting…";
    const xhr = new XMLHttpRequest();
    xhr.open("POST", VTD.API + "/sequences");
    for (const [k, v] of Object.entries(VTD.authHeaders())) xhr.setRequestHeader(k, v);
    const t0 = performance.now();
    xhr.upload.onprogress = (ev) => {
      const n = ev.lengthComputable ? ev.total : total;
      bar.value = n ? ev.loaded / n : 0;
      const rate = ev.loaded / Math.max(0.001, (performance.now() - t0) / 1000);
      text.textContent = `${bytes(ev.loaded)} of ${bytes(n)} (${Math.round(100 * bar.value)} %) · ${bytes(rate)}/s`;
    };
    xhr.upload.onload = () => { bar.removeAttribute("value"); text.textContent = "uploaded; unpacking and checking the sequence…"; };
    xhr.onerror = () => done(VTD.errorFrom(0, ""));
    // The api drops a half-received upload (no files, no row): nothing to clean up here.
    cancel.onclick = () => xhr.abort();
    xhr.onabort = () => {
      done(null);
      $("upload-progress").hidden = true;
      const note = $("upload-note");
      note.textContent = "Upload cancelled; nothing was stored.";
      note.hidden = false;
    };
    xhr.onload = () => {
      if (xhr.status === 201) {
        const seq = JSON.parse(xhr.responseText);
        bar.value = 1;
        text.textContent = `added "${seq.name}": ${seq.frames} frames${seq.has_groundtruth ? ", with ground truth" : ""}`;
        done(null);
        fileInput.value = ""; choose(null); $("seq-name").value = "";
        load();
      } else if (xhr.status === 401 && !retried && VTD.askToken()) upload(form, total, true);
      else if (xhr.status === 409) { done(null); $("upload-progress").hidden = true; duplicateRefused(VTD.errorFrom(409, xhr.responseText), form.get("camera")); }
      else done(VTD.errorFrom(xhr.status, xhr.responseText));
    };
    function done(err) {
      uploadBtn.disabled = !chosen;
      cancel.hidden = true;
      if (err) { $("upload-progress").hidden = true; showError(errBox, err, "Upload refused"); }
    }
    xhr.send(form);
  }

  // ---- the list ----
  const presets = () => [...document.querySelectorAll('input[name="preset"]:checked')].map((c) => c.value);
  const selected = () => [...document.querySelectorAll("input.seq-sel:checked")].map((c) => c.value);
  /** A batch name from the selection, e.g. "walking_xyz +2 · full vs orb-only". */
  function proposedName() {
    const ids = selected(), p = presets();
    if (!ids.length || !p.length) return "";
    const first = document.querySelector(`tr[data-id="${ids[0]}"]`);
    const name = first ? first.dataset.name : ids[0].slice(0, 8);
    return `${name}${ids.length > 1 ? ` +${ids.length - 1}` : ""} · ${p.join(" vs ")}`.slice(0, 255);
  }
  function syncButtons() {
    const p = presets().length;
    $("batch-btn").disabled = !(selected().length && p);
    $("batch-name").placeholder = proposedName() || "proposed from the selection";
    for (const b of document.querySelectorAll("button.run")) {
      b.disabled = !p;
      b.textContent = p > 1 ? `Run ${p} presets` : "Run";
    }
  }
  document.addEventListener("change", (e) => { if (e.target.matches('input[name="preset"], input.seq-sel')) syncButtons(); });
  $("select-all").addEventListener("change", (e) => {
    for (const c of document.querySelectorAll("input.seq-sel")) c.checked = e.target.checked;
    syncButtons();
  });

  function cameraText(c) {
    if (!c) return "—";
    if (c.preset) return c.preset;
    return c.name || `fx ${num(c.fx, 1)}, fy ${num(c.fy, 1)}`;
  }

  function latestRun(job) {
    if (!job) return el("span", { class: "muted small" }, "not run yet");
    const pct = job.status === "running" ? ` ${Math.round(100 * (job.progress || 0))} %` : "";
    return el("a", { href: "/jobs/" + job.id, class: "latest", title: `newest job ${job.id}` },
      statusBadge(job.status), el("span", { class: "small" }, ` ${job.preset}${pct}`));
  }

  function row(seq) {
    const thumb = el("img", { class: "thumb", src: seq.thumbnail_url, alt: "", loading: "lazy", width: 64, height: 48 });
    thumb.addEventListener("error", () => { thumb.style.visibility = "hidden"; });
    // The actions sit under the name, so they stay on screen when a narrow table scrolls sideways.
    const actions = el("div", { class: "row-actions" },
      el("button", { type: "button", class: "run primary small", onclick: () => runOne(seq) }, "Run"),
      el("button", { type: "button", class: "small", title: "Delete the sequence, its jobs and their files", onclick: () => remove(seq) }, "Delete"));
    return el("tr", { "data-id": seq.id, "data-name": seq.name },
      el("td", { class: "sel" }, el("input", { type: "checkbox", class: "seq-sel", value: seq.id, "aria-label": "select " + seq.name })),
      el("td", {}, thumb),
      el("td", { class: "name" }, el("b", {}, seq.name), el("div", { class: "muted small" }, el("code", {}, seq.id.slice(0, 8))), actions),
      el("td", {}, latestRun(seq.latest_job)),
      el("td", { class: "n" }, String(seq.frames)),
      el("td", { class: "n" }, seconds(seq.duration_s)),
      el("td", { class: "n" }, bytes(seq.size_bytes)),
      el("td", {}, cameraText(seq.camera)),
      el("td", {}, seq.has_groundtruth ? el("span", { class: "badge gt", title: "ATE and RPE will be computed" }, "GT")
        : el("span", { class: "badge nogt", title: "no groundtruth.txt: no ATE/RPE" }, "no GT")),
      el("td", { class: "small" }, when(seq.created_at)));
  }

  let reloadTimer = null;
  async function load() {
    clearTimeout(reloadTimer);
    try {
      const page = await api("/sequences?limit=200");
      const keep = new Set(selected()); // a refresh keeps what the user ticked
      const body = $("seq-body");
      body.replaceChildren(...(page.items.length ? page.items.map(row)
        : [el("tr", {}, el("td", { colspan: 10, class: "muted" }, "No sequences yet: upload one above."))]));
      for (const c of document.querySelectorAll("input.seq-sel")) c.checked = keep.has(c.value);
      showError($("seq-error"), null);
      syncButtons();
      // While a sequence's newest run is under way its "Latest run" cell follows it.
      if (page.items.some((q) => q.latest_job && !VTD.TERMINAL.has(q.latest_job.status))) reloadTimer = setTimeout(load, 4000);
    } catch (err) { showError($("seq-error"), err, "Could not list the sequences"); }
  }

  async function runOne(seq) {
    const p = presets();
    try {
      if (p.length === 1) {
        const job = await api("/jobs", { method: "POST", json: { sequence_id: seq.id, preset: p[0] } });
        location.href = "/jobs/" + job.id;
      } else {
        const b = await api("/batches", { method: "POST", json: { sequence_ids: [seq.id], presets: p, name: seq.name } });
        location.href = "/batches/" + b.id;
      }
    } catch (err) { showError($("seq-error"), err, "Could not start the run"); }
  }

  $("batch-btn").addEventListener("click", async () => {
    try {
      const name = $("batch-name").value.trim() || proposedName();
      const b = await api("/batches", { method: "POST", json: { sequence_ids: selected(), presets: presets(), name } });
      location.href = "/batches/" + b.id;
    } catch (err) { showError($("seq-error"), err, "Could not start the batch"); }
  });

  async function remove(seq) {
    if (!confirm(`Delete "${seq.name}", its jobs and all their files?`)) return;
    try { await api("/sequences/" + seq.id, { method: "DELETE" }); toast(`Deleted "${seq.name}"`); load(); }
    catch (err) { showError($("seq-error"), err, "Could not delete"); }
  }

  load();
})();
