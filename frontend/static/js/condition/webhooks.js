/* Condition page (admins): the webhooks that receive the alerts of new flags and places, and their
 * delivery log; add, test and delete a webhook. */
(function () {
  "use strict";
  const C = window.trackvkfCondition;
  const { T, $, state } = C;

  async function drawWebhooks() {
    if (!state.me || state.me.role !== "admin") return;
    $("webhooks-card").hidden = false;
    const [hooks, log] = await Promise.all([T.api.get("/webhooks"), T.api.get("/webhooks/deliveries", { limit: 20 })]);
    $("webhooks-body").innerHTML = hooks.items.length ? hooks.items.map((h) => `<tr data-hook="${h.id}"><td>${h.id}</td><td translate="no">${T.esc(h.url)}</td>
      <td translate="no">${T.esc(h.description || "")}</td><td>${T.esc(h.active ? T._("yes") : T._("no"))}</td><td class="num">${h.pending}</td><td class="num">${h.failed}</td>
      <td><button class="btn small" type="button" data-act="ping">${T.esc(T._("Test"))}</button> <button class="btn small danger" type="button" data-act="delete">${T.esc(T._("Delete"))}</button></td></tr>`).join("")
      : `<tr><td colspan="7" class="muted">${T.esc(T._("No webhook yet: alerts of new flags go nowhere."))}</td></tr>`;
    $("deliveries-body").innerHTML = log.items.length ? log.items.map((d) => `<tr><td>${d.id}</td><td>${d.webhook_id}</td><td translate="no">${T.esc(d.event)}</td>
      <td>${d.run_id ?? "–"}</td><td>${T.esc(d.status)}</td><td class="num">${d.attempts}</td>
      <td translate="no">${d.last_status_code ? "HTTP " + d.last_status_code : T.esc((d.last_error || "–").slice(0, 60))}</td><td>${T.datetime(d.created_at)}</td></tr>`).join("")
      : `<tr><td colspan="8" class="muted">${T.esc(T._("No deliveries yet."))}</td></tr>`;
  }

  $("webhook-form").addEventListener("submit", async (ev) => {
    ev.preventDefault();
    try {
      const h = await T.api.post("/webhooks", { url: $("webhook-url").value, description: $("webhook-desc").value || null });
      $("webhook-secret").textContent = T._("Signing secret of webhook {id} (shown once): {secret}", { id: h.id, secret: h.secret });
      $("webhook-url").value = "";
      await drawWebhooks();
    } catch (e) { T.banner(T._("Webhook not added (HTTP {status}): {detail}", { status: e.status, detail: e.detail })); }
  });
  $("webhooks-body").addEventListener("click", async (ev) => {
    const btn = ev.target.closest("button[data-act]");
    if (!btn) return;
    const id = btn.closest("tr").dataset.hook;
    try {
      if (btn.dataset.act === "delete") await T.api.del(`/webhooks/${id}`);
      else await T.api.post(`/webhooks/${id}/test`);
      await drawWebhooks();
    } catch (e) { T.banner(T._("Webhook {id}: {detail}", { id, detail: e.detail || e.message })); }
  });

  C.drawWebhooks = drawWebhooks;
})();
