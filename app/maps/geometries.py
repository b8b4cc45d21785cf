"""Line geometries (GeoJSON with km stations), imported by engineers: every feature validated in
a child process with a time and memory budget (:func:`app.io.isolation.parse_geojson_upload`,
422 naming the feature or ``crs``), then stored in one transaction with the audit entry
(replacing the same line and track). Rows are answered detached (their columns loaded)."""

from __future__ import annotations

from app.audit import record
from app.core.errors import not_found
from app.core.security import Actor
from app.db import recorder_crud
from app.db.models import LineGeometryRow
from app.db.session import Database
from app.io.geometry import LineGeometry
from app.io.isolation import parse_geojson_upload
from app.settings import Settings

__all__ = ["import_geometries", "geometries", "geometry", "delete_geometry"]


def import_geometries(db: Database, settings: Settings, actor: Actor, data: bytes,
                      filename: str | None) -> list[LineGeometryRow]:
    """Validate every feature of a GeoJSON file, then store them (audited ``geometry.import``).

    Raises
    ------
    RunFileError
        422 naming the feature (``features[i]``) or ``crs``; nothing is stored then.
    """
    parsed = parse_geojson_upload(settings, data)  # in a child process with a time and memory budget
    with db.write() as session:
        rows = recorder_crud.upsert_geometries(session, parsed, actor.name)
        record(session, actor, "geometry.import", target=filename,
               detail={"lines": [[g.line_id, g.track] for g in parsed]})
        return rows


def geometries(db: Database, line_id: str | None = None) -> list[LineGeometryRow]:
    """The stored geometries (of one line if given)."""
    with db.read() as session:
        return recorder_crud.list_geometries(session, line_id)


def geometry(db: Database, geometry_id: int) -> tuple[LineGeometryRow, LineGeometry]:
    """A stored geometry: its row and its vertices; 404 naming ``geometry``."""
    with db.read() as session:
        row = recorder_crud.get_geometry(session, geometry_id)
        if row is None:
            raise not_found("geometry", geometry_id)
        return row, recorder_crud.to_line_geometry(row)


def delete_geometry(db: Database, actor: Actor, geometry_id: int) -> None:
    """Delete a stored geometry (audited ``geometry.delete``; runs placed with it keep their km);
    404 naming ``geometry``."""
    with db.write() as session:
        if not recorder_crud.delete_geometry(session, geometry_id):
            raise not_found("geometry", geometry_id)
        record(session, actor, "geometry.delete", target=geometry_id)
