/* The one fetch wrapper of the dashboard: every request to the server goes through it, and the
 * page's language.
 *
 * - JSON in/out, errors as ApiError(status, detail, field) with the API's message
 *   ({"detail": "<field>: <message>", "field": ...}, in the page's language); a request that
 *   does not reach the server is an ApiError too (status 0);
 * - state-changing requests carry X-CSRF-Token from the cookie trackvkf_csrf when present;
 * - a 401 answer navigates to /login?next=<current path>;
 * - T._(msgid, {field: value}), T.ngettext(singular, plural, n, {...}) and T.pgettext(context,
 *   msgid, {...}) translate with the catalogue the page booted with (/i18n/<lang>.js, from the
 *   same gettext catalogues as the server's texts); "{field}" in a message takes the value.
 */
(function () {
  "use strict";
  const boot = JSON.parse(document.getElementById("boot").textContent);
  const API = boot.api || "/api/v1";
  const UNSAFE = new Set(["POST", "PUT", "PATCH", "DELETE"]);
  const CATALOGUE = window.trackvkfI18n || { code: "en", messages: {}, plural: ["one", "other"], plotly: null };
  const LANG = boot.lang || CATALOGUE.code || "en";
  const LOCALE = boot.locale || LANG;
  const plurals = new Intl.PluralRules(LOCALE);

  function fill(text, params) {
    if (!params) return text;
    return text.replace(/\{(\w+)\}/g, (all, name) => (name in params ? String(params[name]) : all));
  }
  function _(msgid, params) {
    const t = CATALOGUE.messages[msgid];
    return fill(typeof t === "string" ? t : msgid, params);
  }
  function pgettext(context, msgid, params) {
    const t = CATALOGUE.messages[context + "\u0004" + msgid];
    return fill(typeof t === "string" ? t : msgid, params);
  }
  function ngettext(singular, plural, n, params) {
    const forms = CATALOGUE.messages[singular];
    const all = Object.assign({ n }, params || {});
    if (Array.isArray(forms)) {
      let i = CATALOGUE.plural.indexOf(plurals.select(n));
      if (i < 0 || i >= forms.length) i = forms.length - 1;
      return fill(forms[i], all);
    }
    return fill(n === 1 ? singular : plural, all);
  }

  class ApiError extends Error {
    constructor(status, detail, field) {
      super(detail || `HTTP ${status}`);
      this.status = status;
      this.detail = detail || `HTTP ${status}`;
      this.field = field || null;
    }
  }

  function cookie(name) {
    const hit = document.cookie.split(";").map((c) => c.trim()).find((c) => c.startsWith(name + "="));
    return hit ? decodeURIComponent(hit.slice(name.length + 1)) : null;
  }

  function toLogin() {
    const next = window.location.pathname + window.location.search;
    window.location.assign("/login?next=" + encodeURIComponent(next));
  }

  function url(path, params) {
    const u = new URL(path.startsWith("/api/") ? path : API + path, window.location.origin);
    if (params) {
      for (const [k, v] of Object.entries(params)) {
        if (v !== undefined && v !== null && v !== "") u.searchParams.set(k, v);
      }
    }
    return u.pathname + u.search;
  }

  function headers(method, extra) {
    const h = Object.assign({ Accept: "application/json" }, extra || {});
    const csrf = cookie("trackvkf_csrf");
    if (csrf && UNSAFE.has(method)) h["X-CSRF-Token"] = csrf;
    return h;
  }

  async function errorOf(status, text) {
    let detail = text, field = null;
    try {
      const body = JSON.parse(text);
      if (typeof body.detail === "string") detail = body.detail;
      else if (Array.isArray(body.detail)) {
        detail = body.detail.map((d) => `${(d.loc || []).slice(1).join(".")}: ${d.msg}`).join("; ");
      }
      field = body.field || null;
    } catch (e) { /* not JSON */ }
    return new ApiError(status, detail, field);
  }

  async function request(method, path, { params, json, body, headers: extra } = {}) {
    const init = { method, headers: headers(method, extra), credentials: "same-origin" };
    if (json !== undefined) {
      init.body = JSON.stringify(json);
      init.headers["Content-Type"] = "application/json";
    } else if (body !== undefined) {
      init.body = body;
    }
    let res;
    try {
      res = await fetch(url(path, params), init);
    } catch (e) {  // no answer at all: the server is down or the network is gone
      throw new ApiError(0, _("network error: the server could not be reached"), "network");
    }
    if (res.status === 401) { toLogin(); throw new ApiError(401, _("authentication required")); }
    const text = res.status === 204 ? "" : await res.text();
    if (!res.ok) throw await errorOf(res.status, text);
    return text ? JSON.parse(text) : null;
  }

  /* Upload with progress (XMLHttpRequest: fetch has no upload progress). */
  function upload(path, formData, onProgress) {
    return new Promise((resolve, reject) => {
      const xhr = new XMLHttpRequest();
      xhr.open("POST", url(path));
      const h = headers("POST");
      for (const [k, v] of Object.entries(h)) xhr.setRequestHeader(k, v);
      xhr.withCredentials = true;
      xhr.upload.onprogress = (e) => { if (e.lengthComputable && onProgress) onProgress(e.loaded / e.total); };
      xhr.onload = async () => {
        if (xhr.status === 401) { toLogin(); reject(new ApiError(401, _("authentication required"))); return; }
        if (xhr.status >= 200 && xhr.status < 300) {
          resolve({ status: xhr.status, body: xhr.responseText ? JSON.parse(xhr.responseText) : null });
        } else {
          reject(await errorOf(xhr.status, xhr.responseText));
        }
      };
      xhr.onerror = () => reject(new ApiError(0, _("network error: the server could not be reached"), "network"));
      xhr.send(formData);
    });
  }

  document.addEventListener("DOMContentLoaded", () => {
    const out = document.getElementById("logout");
    if (out) {
      out.addEventListener("click", async () => {
        let answer = null;
        try { answer = await request("POST", "/auth/logout"); } catch (e) { /* already logged out */ }
        /* a session begun at the OpenID provider: sign out there too (it comes back to /login) */
        window.location.assign(answer && answer.end_session_url ? answer.end_session_url : "/login");
      });
    }
    // the language kept with the account ("" = the browser's): the page comes back in it
    const picker = document.getElementById("lang-picker");
    if (picker) {
      picker.addEventListener("change", async () => {
        try {
          await request("PATCH", "/auth/me", { json: { language: picker.value || null } });
          window.location.reload();
        } catch (e) {
          const b = document.getElementById("banner");
          if (b) { b.textContent = _("Language not changed: {detail}", { detail: e.detail || e.message }); b.hidden = false; }
        }
      });
    }
  });

  /* A profile (GET /runs/{id}/profile) in the compact column layout, returned as the row layout:
   * {...head, rows: [{km, sleeper_amp, ...}, ...]} with the wheel on every row. The server sends one
   * array per column with fixed decimals (about a third of the bytes, gzip-compressed on the wire),
   * an ETag the browser revalidates with, and keeps recent answers in memory. */
  async function profile(path, params) {
    const body = await request("GET", path, { params: Object.assign({}, params, { layout: "columns" }) });
    const names = body.columns;
    const cols = names.map((c) => body.data[c]);
    const n = body.n_rows;
    const rows = new Array(n);
    for (let i = 0; i < n; i++) {
      const row = { wheel: body.wheel };
      for (let j = 0; j < names.length; j++) row[names[j]] = cols[j][i];
      rows[i] = row;
    }
    delete body.data;
    body.rows = rows;
    return body;
  }

  window.trackvkf = Object.assign(window.trackvkf || {}, {
    boot,
    ApiError,
    lang: LANG,
    locale: LOCALE,
    catalogue: CATALOGUE,
    _, ngettext, pgettext,
    api: {
      get: (path, params) => request("GET", path, { params }),
      post: (path, json) => request("POST", path, { json }),
      patch: (path, json) => request("PATCH", path, { json }),
      del: (path) => request("DELETE", path),
      upload,
      url,
      profile,
      /* GET that answers null for 404 (a resource or feature that does not exist yet). */
      async optional(path, params) {
        try { return await request("GET", path, { params }); }
        catch (e) { if (e.status === 404) return null; throw e; }
      },
    },
  });
})();
