"""Running the service: worker liveness and queue health (:mod:`~app.operations.liveness`),
backup and restore (:mod:`~app.operations.backup`)."""
