/* Runs page: filters, live job status, upload with progress, cancel / reprocess / delete. */
(function () {
  "use strict";
  const T = window.trackvkf;
  const body = document.getElementById("runs-body");
  let runs = [];
  let timer = null;
  let watchJob = null;

  function filters() {
    return {
      line_id: document.getElementById("f-line").value,
      vehicle_id: document.getElementById("f-vehicle").value,
      date_from: document.getElementById("f-from").value,
      date_to: document.getElementById("f-to").value,
    };
  }

  function kmRange(r) {
    const len = (r.summary.distance_m || 0) / 1000;
    if (r.km_start === null || r.km_start === undefined) return [null, null, len];
    const end = r.km_increasing === false ? r.km_start - len : r.km_start + len;
    return [Math.min(r.km_start, end), Math.max(r.km_start, end), len];
  }

  function jobCell(job) {
    if (!job) return [`<span class="badge queued">${T.esc(T._("no job"))}</span>`, ""];
    const pct = Math.round(100 * (job.progress || 0));
    const badge = `<span class="badge ${T.esc(job.status)}" data-status="${T.esc(job.status)}" title="${T.esc(job.error || "")}">${T.esc(T.jobStatus(job.status))}</span>`;
    const chunks = T._("{done}/{total} chunks", { done: job.chunks_done, total: job.n_chunks ?? "?" });
    const bar = `<span class="progress" title="${T.esc(chunks)}"><span style="width:${pct}%"></span></span> <span class="muted">${T.fmt(pct, 0)} %</span>`;
    return [badge, bar];
  }

  function actions(r) {
    const job = r.latest_job;
    const active = job && (job.status === "queued" || job.status === "running");
    const done = job && job.status === "done";
    const out = [];
    if (done) {
      out.push(`<a class="btn small" href="/runs/${r.id}">${T._("Stiffness map")}</a>`);
      out.push(`<a class="btn small" href="/runs/${r.id}/spectrogram">${T._("Spectrogram")}</a>`);
      if (r.vehicle_id) out.push(`<a class="btn small" href="/wheels?vehicle_id=${encodeURIComponent(r.vehicle_id)}&run_id=${r.id}">${T._("Wheels")}</a>`);
    }
    if (active) out.push(`<button class="btn small danger" data-act="cancel" data-job="${job.id}">${T._("Cancel")}</button>`);
    else out.push(`<button class="btn small" data-act="reprocess" data-run="${r.id}">${T._("Reprocess")}</button>`);
    return out.join(" ");
  }

  function render() {
    document.getElementById("runs-count").textContent = T.ngettext("{n} run", "{n} runs", runs.length);
    if (!runs.length) {
      body.innerHTML = `<tr><td colspan="12"><div class="empty"><strong>${T._("No runs match.")}</strong>
        ${T._("Upload a run file above, or run {command}.", { command: "<code>trackvkf demo</code>" })}</div></td></tr>`;
      return;
    }
    body.innerHTML = runs.map((r) => {
      const [a, b, len] = kmRange(r);
      const [badge, bar] = jobCell(r.latest_job);
      return `<tr data-run="${r.id}">
        <td class="num">${r.id}</td><td>${T.datetime(r.start_time)}</td><td translate="no">${T.esc(r.vehicle_id)}</td>
        <td translate="no">${T.esc(r.line_id)} / ${T.esc(r.track)}</td><td translate="no">${T.esc(r.direction)}</td>
        <td class="num">${T.fmt(a)}</td><td class="num">${T.fmt(b)}</td><td class="num">${T.fmt(len, 2)}</td>
        <td class="muted file" translate="no" title="${T.esc(r.original_filename || "")} · sha256 ${T.esc(r.sha256)}">${T.esc(r.original_filename || "")}</td>
        <td class="job-status">${badge}</td><td>${bar}</td><td class="actions"><div class="btns">${actions(r)}</div></td></tr>`;
    }).join("");
  }

  async function loadFilterOptions() {
    const all = await T.allRuns();
    const lines = [...new Set(all.map((r) => r.line_id).filter(Boolean))].sort();
    const vehicles = [...new Set(all.map((r) => r.vehicle_id).filter(Boolean))].sort();
    const fill = (id, values, label) => {
      const sel = document.getElementById(id);
      const cur = sel.value;
      sel.innerHTML = `<option value="">${label}</option>` + values.map((v) => `<option>${T.esc(v)}</option>`).join("");
      sel.value = values.includes(cur) ? cur : "";
    };
    fill("f-line", lines, T._("all lines"));
    fill("f-vehicle", vehicles, T._("all vehicles"));
  }

  async function refresh() {
    try {
      const page = await T.api.get("/runs", Object.assign({ limit: 200 }, filters()));
      runs = page.items;
      render();
      updateWatched();
      const active = runs.some((r) => r.latest_job && ["queued", "running"].includes(r.latest_job.status));
      schedule(active || watchJob ? 1000 : 5000);
    } catch (e) {
      T.banner(T._("Could not load the runs: {detail}", { detail: e.detail || e.message }));
      schedule(5000);
    }
  }

  function schedule(ms) {
    clearTimeout(timer);
    timer = setTimeout(refresh, ms);
  }

  function setUploadStatus(text, pct) {
    document.getElementById("upload-status").textContent = text;
    if (pct !== undefined) document.querySelector("#upload-progress > span").style.width = `${Math.round(pct * 100)}%`;
  }

  function updateWatched() {
    if (!watchJob) return;
    const r = runs.find((x) => x.id === watchJob.run);
    const job = r && r.latest_job;
    if (!job) return;
    const pct = Math.round(100 * (job.progress || 0));
    const args = { run: r.id, job: job.id, status: T.jobStatus(job.status), pct: T.fmt(pct, 0), error: job.error || "" };
    if (job.status === "done") {
      setUploadStatus(T._("Run {run}: processing job {job} done.", args), 1);
      watchJob = null;
    } else if (job.status === "failed" || job.status === "cancelled") {
      setUploadStatus(job.error ? T._("Run {run}: processing job {job} {status}: {error}", args)
        : T._("Run {run}: processing job {job} {status}", args), 1);
      watchJob = null;
    } else {
      setUploadStatus(T._("Run {run} uploaded: processing job {job} {status} ({pct} %)…", args), 1);
    }
  }

  document.getElementById("upload-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    T.banner(null);
    const file = document.getElementById("upload-file").files[0];
    if (!file) { T.banner(T._("Choose a run file to upload.")); return; }
    const meta = document.getElementById("upload-metadata").value.trim();
    const form = new FormData();
    form.append("file", file, file.name);
    if (meta) form.append("metadata", meta);
    const button = document.getElementById("upload-button");
    button.disabled = true;
    setUploadStatus(T._("Uploading {file}…", { file: file.name }), 0);
    try {
      const { status, body: run } = await T.api.upload("/runs", form,
        (f) => setUploadStatus(T._("Uploading {file}: {pct} %", { file: file.name, pct: T.fmt(f * 100, 0) }), f));
      if (status === 200) setUploadStatus(T._("{file} was uploaded before: run {run}.", { file: file.name, run: run.id }), 1);
      else setUploadStatus(T._("Run {run} uploaded: processing job {job} queued…", { run: run.id, job: run.latest_job ? run.latest_job.id : "?" }), 1);
      watchJob = { run: run.id };
      await loadFilterOptions();
      await refresh();
    } catch (e) {
      setUploadStatus(T._("Upload rejected."), 0);
      T.banner(T._("Upload rejected (HTTP {status}): {detail}", { status: e.status, detail: e.detail }));
    } finally {
      button.disabled = false;
    }
  });

  body.addEventListener("click", async (ev) => {
    const btn = ev.target.closest("button[data-act]");
    if (!btn) return;
    btn.disabled = true;
    try {
      if (btn.dataset.act === "cancel") {
        await T.api.post(`/jobs/${btn.dataset.job}/cancel`);
        T.banner(T._("Cancel requested for job {job}.", { job: btn.dataset.job }), "info");
      } else if (btn.dataset.act === "reprocess") {
        const job = await T.api.post(`/runs/${btn.dataset.run}/jobs`, {});
        T.banner(T._("Run {run}: reprocessing job {job} queued.", { run: btn.dataset.run, job: job.id }), "info");
      }
    } catch (e) {
      const args = { status: e.status, detail: e.detail };
      T.banner(btn.dataset.act === "cancel" ? T._("Cancel failed (HTTP {status}): {detail}", args)
        : T._("Reprocessing failed (HTTP {status}): {detail}", args));
    }
    refresh();
  });

  document.getElementById("filters").addEventListener("submit", (ev) => { ev.preventDefault(); refresh(); });
  document.getElementById("f-reset").addEventListener("click", () => setTimeout(refresh, 0));

  /* CSV of the runs table */
  document.querySelector('button[data-csv-for="runs-table-csv"]').addEventListener("click", () => {
    const cols = ["run_id", "start_time", "vehicle_id", "line_id", "track", "direction", "km_from", "km_to",
      "length_km", "file", "sha256", "job_id", "job_status", "job_progress"];
    const rows = runs.map((r) => {
      const [a, b, len] = kmRange(r);
      const j = r.latest_job || {};
      return [r.id, r.start_time, r.vehicle_id, r.line_id, r.track, r.direction, a, b, len,
        r.original_filename, r.sha256, j.id, j.status, j.progress];
    });
    T.downloadCSV("trackvkf-runs.csv", cols, rows);  // header labels in the page's language
  });

  (async () => {
    try { await loadFilterOptions(); } catch (e) { T.banner(T._("Could not load the runs: {detail}", { detail: e.detail || e.message })); }
    await refresh();
    document.querySelector('button[data-csv-for="runs-table-csv"]').disabled = false;
    T.ready();
  })();
})();
