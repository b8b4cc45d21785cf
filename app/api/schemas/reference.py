"""Schemas of the reference data endpoints."""

from __future__ import annotations

import datetime as dt

from pydantic import BaseModel, Field

__all__ = ["ImportOut", "SubsidenceItem", "MaintenanceItem", "SuperstructureItem",
           "SubsidenceList", "MaintenanceList", "SuperstructureList", "DeleteOut"]


class ImportOut(BaseModel):
    kind: str = Field(description="subsidence, maintenance or superstructure")
    imported: int = Field(description="rows imported")
    replaced: int = Field(0, description="rows deleted first (mode=replace)")


class DeleteOut(BaseModel):
    kind: str
    deleted: int


class SubsidenceItem(BaseModel):
    id: int
    line_id: str
    track: str
    km: float
    rail: int | None = Field(None, description="1 right, 2 left, null = both rails")
    subsidence_mm: float = Field(description="subsidence, mm (negative = down)")
    date: dt.date


class MaintenanceItem(BaseModel):
    id: int
    line_id: str
    track: str
    km_from: float
    km_to: float
    type: str = Field(description="tamping, grinding, rail_replacement, ballast_cleaning or other")
    date: dt.date


class SuperstructureItem(BaseModel):
    id: int
    line_id: str
    track: str
    km_from: float
    km_to: float
    type: str
    details: str | None = None


class SubsidenceList(BaseModel):
    items: list[SubsidenceItem]
    truncated: bool = False


class MaintenanceList(BaseModel):
    items: list[MaintenanceItem]
    truncated: bool = False


class SuperstructureList(BaseModel):
    items: list[SuperstructureItem]
    truncated: bool = False
