/* Sequences page: drag-and-drop upload with progress, the list, starting jobs and batches. */
"use strict";
(() => {
  const { api, el, showError, toast, num, bytes, seconds, when } = VTD;
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
    if (chosen && !/\.(zip|tgz|tar\.gz|tar)$/i.test(chosen.name)) {
      showError($("upload-error"), new Error(`"${chosen.name}" is not a .zip, .tar.gz or .tgz archive; the server will likely refuse it`));
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
    const form = new FormData();
    form.append("camera", camera);
    const name = $("seq-name").value.trim();
    if (name) form.append("name", name);
    form.append("file", chosen, chosen.name); // last: the server reads the fields first
    upload(form, chosen.size);
  });

  function upload(form, total, retried = false) {
    const bar = $("upload-bar"), text = $("upload-text"), errBox = $("upload-error");
    showError(errBox, null);
    $("upload-progress").hidden = false;
    uploadBtn.disabled = true;
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
    xhr.onload = () => {
      if (xhr.status === 201) {
        const seq = JSON.parse(xhr.responseText);
        bar.value = 1;
        text.textContent = `added "${seq.name}": ${seq.frames} frames${seq.has_groundtruth ? ", with ground truth" : ""}`;
        done(null);
        fileInput.value = ""; choose(null); $("seq-name").value = "";
        load();
      } else if (xhr.status === 401 && !retried && VTD.askToken()) upload(form, total, true);
      else done(VTD.errorFrom(xhr.status, xhr.responseText));
    };
    function done(err) {
      uploadBtn.disabled = !chosen;
      if (err) { $("upload-progress").hidden = true; showError(errBox, err, "Upload refused"); }
    }
    xhr.send(form);
  }

  // ---- the list ----
  const presets = () => [...document.querySelectorAll('input[name="preset"]:checked')].map((c) => c.value);
  const selected = () => [...document.querySelectorAll("input.seq-sel:checked")].map((c) => c.value);
  function syncButtons() {
    const p = presets().length;
    $("batch-btn").disabled = !(selected().length && p);
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

  function row(seq) {
    const thumb = el("img", { class: "thumb", src: seq.thumbnail_url, alt: "", loading: "lazy", width: 64, height: 48 });
    thumb.addEventListener("error", () => { thumb.style.visibility = "hidden"; });
    return el("tr", { "data-id": seq.id },
      el("td", { class: "sel" }, el("input", { type: "checkbox", class: "seq-sel", value: seq.id, "aria-label": "select " + seq.name })),
      el("td", {}, thumb),
      el("td", {}, el("b", {}, seq.name), el("div", { class: "muted small" }, el("code", {}, seq.id.slice(0, 8)))),
      el("td", { class: "n" }, String(seq.frames)),
      el("td", { class: "n" }, seconds(seq.duration_s)),
      el("td", { class: "n" }, bytes(seq.size_bytes)),
      el("td", {}, cameraText(seq.camera)),
      el("td", {}, seq.has_groundtruth ? el("span", { class: "badge gt", title: "ATE and RPE will be computed" }, "GT")
        : el("span", { class: "badge nogt", title: "no groundtruth.txt: no ATE/RPE" }, "no GT")),
      el("td", { class: "small" }, when(seq.created_at)),
      el("td", {}, el("button", { type: "button", class: "run primary small", onclick: () => runOne(seq) }, "Run"), " ",
        el("button", { type: "button", class: "small", title: "Delete the sequence, its jobs and their files", onclick: () => remove(seq) }, "Delete")));
  }

  async function load() {
    try {
      const page = await api("/sequences?limit=200");
      const body = $("seq-body");
      body.replaceChildren(...(page.items.length ? page.items.map(row)
        : [el("tr", {}, el("td", { colspan: 10, class: "muted" }, "No sequences yet: upload one above."))]));
      showError($("seq-error"), null);
      syncButtons();
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
      const b = await api("/batches", { method: "POST", json: { sequence_ids: selected(), presets: presets() } });
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
