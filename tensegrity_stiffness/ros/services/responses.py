"""What every service answer shares: a refused request (:func:`fail`)."""

from __future__ import annotations

from typing import Any


def fail(response: Any, message: str) -> Any:
    """``success: false`` with ``message``."""
    response.success = False
    response.message = message
    return response
