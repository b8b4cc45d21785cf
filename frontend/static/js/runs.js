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
    if (!job) return ['<span class="badge queued">no job</span>', ""];
    const pct = Math.round(100 * (job.progress || 0));
    const badge = `<span class="badge ${T.esc(job.status)}" title="${T.esc(job.error || "")}">${T.esc(job.status)}</span>`;
    const bar = `<span class="progress" title="${job.chunks_done}/${job.n_chunks ?? "?"} chunks"><span style="width:${pct}%"></span></span> <span class="muted">${pct} %</span>`;
    return [badge, bar];
  }

  function actions(r) {
    const job = r.latest_job;
    const active = job && (job.status === "queued" || job.status === "running");
    const done = job && job.status === "done";
    const out = [];
    if (done) {
      out.push(`<a class="btn small" href="/runs/${r.id}">Stiffness map</a>`);
      out.push(`<a class="btn small" href="/runs/${r.id}/spectrogram">Spectrogram</a>`);
      if (r.vehicle_id) out.push(`<a class="btn small" href="/wheels?vehicle_id=${encodeURIComponent(r.vehicle_id)}&run_id=${r.id}">Wheels</a>`);
    }
    if (active) out.push(`<button class="btn small danger" data-act="cancel" data-job="${job.id}">Cancel</button>`);
    else out.push(`<button class="btn small" data-act="reprocess" data-run="${r.id}">Reprocess</button>`);
    return out.join(" ");
  }

  function render() {
    document.getElementById("runs-count").textContent = `${runs.length} run${runs.length === 1 ? "" : "s"}`;
    if (!runs.length) {
      body.innerHTML = `<tr><td colspan="12"><div class="empty"><strong>No runs match.</strong>
        Upload a run file above, or run <code>trackvkf demo</code>.</div></td></tr>`;
      return;
    }
    body.innerHTML = runs.map((r) => {
      const [a, b, len] = kmRange(r);
      const [badge, bar] = jobCell(r.latest_job);
      return `<tr data-run="${r.id}">
        <td class="num">${r.id}</td><td>${T.datetime(r.start_time)}</td><td>${T.esc(r.vehicle_id)}</td>
        <td>${T.esc(r.line_id)} / ${T.esc(r.track)}</td><td>${T.esc(r.direction)}</td>
        <td class="num">${T.fmt(a)}</td><td class="num">${T.fmt(b)}</td><td class="num">${T.fmt(len, 2)}</td>
        <td class="muted file" title="${T.esc(r.original_filename || "")} · sha256 ${T.esc(r.sha256)}">${T.esc(r.original_filename || "")}</td>
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
    fill("f-line", lines, "all lines");
    fill("f-vehicle", vehicles, "all vehicles");
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
      T.banner(`Could not load the runs: ${e.detail || e.message}`);
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
    if (job.status === "done") {
      setUploadStatus(`Run ${r.id}: processing job ${job.id} done.`, 1);
      watchJob = null;
    } else if (job.status === "failed" || job.status === "cancelled") {
      setUploadStatus(`Run ${r.id}: processing job ${job.id} ${job.status}${job.error ? ": " + job.error : ""}`, 1);
      watchJob = null;
    } else {
      setUploadStatus(`Run ${r.id} uploaded: processing job ${job.id} ${job.status} (${pct} %)…`, 1);
    }
  }

  document.getElementById("upload-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    T.banner(null);
    const file = document.getElementById("upload-file").files[0];
    if (!file) { T.banner("Choose a run file to upload."); return; }
    const meta = document.getElementById("upload-metadata").value.trim();
    const form = new FormData();
    form.append("file", file, file.name);
    if (meta) form.append("metadata", meta);
    const button = document.getElementById("upload-button");
    button.disabled = true;
    setUploadStatus(`Uploading ${file.name}…`, 0);
    try {
      const { status, body: run } = await T.api.upload("/runs", form, (f) => setUploadStatus(`Uploading ${file.name}: ${Math.round(f * 100)} %`, f));
      if (status === 200) setUploadStatus(`${file.name} was uploaded before: run ${run.id}.`, 1);
      else setUploadStatus(`Run ${run.id} uploaded: processing job ${run.latest_job ? run.latest_job.id : "?"} queued…`, 1);
      watchJob = { run: run.id };
      await loadFilterOptions();
      await refresh();
    } catch (e) {
      setUploadStatus("Upload rejected.", 0);
      T.banner(`Upload rejected (HTTP ${e.status}): ${e.detail}`);
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
        T.banner(`Cancel requested for job ${btn.dataset.job}.`, "info");
      } else if (btn.dataset.act === "reprocess") {
        const job = await T.api.post(`/runs/${btn.dataset.run}/jobs`, {});
        T.banner(`Run ${btn.dataset.run}: reprocessing job ${job.id} queued.`, "info");
      }
    } catch (e) {
      T.banner(`${btn.dataset.act} failed (HTTP ${e.status}): ${e.detail}`);
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
    T.downloadCSV("trackvkf-runs.csv", cols, rows);
  });

  (async () => {
    try { await loadFilterOptions(); } catch (e) { T.banner(`Could not load the runs: ${e.detail || e.message}`); }
    await refresh();
    document.querySelector('button[data-csv-for="runs-table-csv"]').disabled = false;
    T.ready();
  })();
})();
