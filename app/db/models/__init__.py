"""The tables of the service (SQLAlchemy 2.0; portable: SQLite and PostgreSQL), one module a subject.

:mod:`~app.db.models.base` holds the declarative base and the shared column types;
importing this package imports every table module, so ``Base.metadata`` holds every
table (what Alembic and the tests compare the migrations with). A table module
imports only :mod:`~app.db.models.base`; nothing here imports this package back.

=====================  ==============================================================
module                 tables
=====================  ==============================================================
``runs``               runs, jobs, job_chunks, profile_bins, wheel_oor
``condition``          the segment condition store: condition_lines, condition_runs,
                       segment_condition, condition_overview, condition_flags
``curves``             reference_curves (the stiffness index's cache)
``reference``          reference data: ref_subsidence, ref_maintenance, ref_superstructure
``recorder``           channel_maps, line_geometries
``webhooks``           webhooks and their delivery log (the alerts outbox)
``operations``         worker_heartbeats (the liveness of worker processes)
``places``             places, place_observations, place_events, place_status_history,
                       place_actions, place_runs (the work list)
``auth``               users, sessions, api_keys, audit_log
``assets``             assets (known discontinuities: switches, bridges, joints, ...)
=====================  ==============================================================
"""

from app.db.models.assets import ASSET_IMPORT_STATES, NO_TRACK, Asset, AssetImport, AssetLine
from app.db.models.auth import ApiKey, AuditEntry, User, UserSession
from app.db.models.base import NAMING, Base, JSONType, UTCDateTime, utcnow
from app.db.models.condition import (
    FLAG_KINDS,
    ConditionFlag,
    ConditionLine,
    ConditionOverview,
    ConditionRun,
    SegmentCondition,
)
from app.db.models.curves import ReferenceCurveRow
from app.db.models.operations import WorkerHeartbeat
from app.db.models.places import (
    PLACE_ACTION_RELATIONS,
    PLACE_EVENT_KINDS,
    PLACE_STATUSES,
    Place,
    PlaceAction,
    PlaceEventRow,
    PlaceObservation,
    PlaceRun,
    PlacesPending,
    PlaceStatusChange,
)
from app.db.models.recorder import ChannelMapRow, LineGeometryRow
from app.db.models.reference import (
    MAINTENANCE_TYPES,
    MaintenanceAction,
    SubsidenceMeasurement,
    SuperstructureSection,
)
from app.db.models.runs import (
    COARSE_DISPLAY_LEVEL,
    N_ORDER_COLUMNS,
    ORDER_COLUMNS,
    PROFILE_VALUE_COLUMNS,
    ChunkStatus,
    Job,
    JobChunk,
    JobStatus,
    ProfileBin,
    Run,
    WheelOOR,
)
from app.db.models.webhooks import DeliveryStatus, Webhook, WebhookDelivery

__all__ = [
    "ApiKey",
    "Asset",
    "AssetImport",
    "AssetLine",
    "ASSET_IMPORT_STATES",
    "NO_TRACK",
    "AuditEntry",
    "Base",
    "ChannelMapRow",
    "ChunkStatus",
    "COARSE_DISPLAY_LEVEL",
    "ConditionFlag",
    "ConditionLine",
    "ConditionOverview",
    "ConditionRun",
    "DeliveryStatus",
    "FLAG_KINDS",
    "Job",
    "JobChunk",
    "JobStatus",
    "JSONType",
    "LineGeometryRow",
    "MAINTENANCE_TYPES",
    "MaintenanceAction",
    "N_ORDER_COLUMNS",
    "NAMING",
    "ORDER_COLUMNS",
    "Place",
    "PlaceAction",
    "PLACE_ACTION_RELATIONS",
    "PLACE_EVENT_KINDS",
    "PlaceEventRow",
    "PlaceObservation",
    "PlaceRun",
    "PlacesPending",
    "PLACE_STATUSES",
    "PlaceStatusChange",
    "PROFILE_VALUE_COLUMNS",
    "ProfileBin",
    "ReferenceCurveRow",
    "Run",
    "SegmentCondition",
    "SubsidenceMeasurement",
    "SuperstructureSection",
    "User",
    "UserSession",
    "UTCDateTime",
    "utcnow",
    "Webhook",
    "WebhookDelivery",
    "WheelOOR",
    "WorkerHeartbeat",
]
