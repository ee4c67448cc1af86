"""The Blackboard node: every result remembered, durably, and served on request."""
from __future__ import annotations

from blackboard.service import BlackboardService
from blackboard.store import DEFAULT_KEEP, Store, StoredValue, default_db_path, parse_name

__all__ = ["DEFAULT_KEEP", "BlackboardService", "Store", "StoredValue", "default_db_path", "parse_name"]
