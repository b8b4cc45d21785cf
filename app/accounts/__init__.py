"""Accounts: who a request is (API keys, browser sessions), logging in and out, and the
administration of users and API keys, each change audited in its own transaction.

- :mod:`app.accounts.sessions`: the principal of an API key or a session cookie, login,
  logout, a user's own password change;
- :mod:`app.accounts.admin`: users and API keys (admins; the ``trackvkf user``/``key`` commands).

The security primitives (hashes, tokens, CSRF, device cookies) are :mod:`app.core.security`;
the rows and their queries :mod:`app.db.auth_crud`.
"""
