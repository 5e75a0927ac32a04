"""Stability report (issue 11): each failure class provoked, measured against an oracle
independent of the engine, written to docs/stability.md (``python -m bench.stability``)."""
