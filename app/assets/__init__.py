"""Known discontinuities of the track (switches, crossings, bridges, level crossings, insulated
joints, welds): import as reference data (:mod:`~app.assets.reader`, :mod:`~app.assets.service`)
and the labels of the places on them (:mod:`~app.assets.labels`)."""
