"""What the map shows: a profile quantity of a run averaged per segment and placed on the line's
imported geometry (:mod:`~app.maps.indicator`)."""
