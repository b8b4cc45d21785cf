/* The login form: posts the credentials as JSON and goes on to the page asked for
 * (a file, not an inline script: the Content-Security-Policy allows scripts only from the server's files).
 * Its words come from the catalogue the page loaded (/i18n/<lang>.js). */
(function () {
  const messages = (window.trackvkfI18n || {}).messages || {};
  function _(msgid, params) {
    const text = typeof messages[msgid] === "string" ? messages[msgid] : msgid;
    return text.replace(/\{(\w+)\}/g, (all, name) => (params && name in params ? String(params[name]) : all));
  }
  const form = document.getElementById("login");
  const error = document.getElementById("error");
  form.addEventListener("submit", async function (event) {
    event.preventDefault();
    error.textContent = "";
    const body = JSON.stringify({
      username: form.username.value, password: form.password.value,
    });
    let response;
    try {
      response = await fetch("/api/v1/auth/login", {
        method: "POST", headers: {"Content-Type": "application/json"}, body: body,
        credentials: "same-origin",
      });
    } catch (e) {
      error.textContent = _("The server cannot be reached.");
      return;
    }
    if (response.ok) {
      window.location.assign(form.dataset.next || "/");
      return;
    }
    let message = _("Login failed ({status}).", { status: response.status });
    if (response.status === 401) message = _("Wrong user name or password.");
    if (response.status === 429) message = _("Too many attempts; wait a minute and try again.");
    error.textContent = message;
  });
})();
