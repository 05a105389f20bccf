"""Units shared by every package (SI; timestamps are integer nanoseconds)."""

from __future__ import annotations

NS_PER_S = 1_000_000_000
"""Nanoseconds per second: `t_s = t_ns / NS_PER_S`, `t_ns = round(t_s * NS_PER_S)`."""
US_PER_S = 1_000_000
"""Microseconds per second (Oxford file stamps)."""
NS_PER_US = 1_000
"""Nanoseconds per microsecond."""
NS_PER_MS = 1_000_000
"""Nanoseconds per millisecond."""
