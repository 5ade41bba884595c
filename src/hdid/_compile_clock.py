"""Compile time, measured: the wall time JAX spends tracing, lowering and compiling (or
reading its persistent cache), for the batch's and ``diagnose``'s timing reports."""

from __future__ import annotations

import threading


#: Name prefix of the program store's background readers (``_programs.PREFETCH_THREAD``).
BACKGROUND_THREAD = "hdid-programs"


class _CompileClock:
    """Wall time spent tracing, lowering and compiling (or reading the persistent cache).

    JAX reports these phases as monitoring events; nested jits overlap, so the union of
    the spans is kept. Events from the program store's background readers
    (:func:`hdid._problems._programs.prefetch`, threads named ``hdid-programs``) are kept
    apart in ``background``: they overlap the caller's work, and what the caller waits
    for them is counted by the store itself.
    """

    KEYS = (
        "/jax/core/compile/jaxpr_trace_duration",
        "/jax/core/compile/jaxpr_to_mlir_module_duration",
        "/jax/core/compile/backend_compile_duration",
    )

    def __init__(self):
        self.spans: list[tuple[float, float]] = []
        self.background: list[tuple[float, float]] = []
        self.lock = threading.Lock()
        from jax import monitoring

        monitoring.register_event_time_span_listener(self._span)

    def _span(self, event, start, end, **_):
        if event in self.KEYS:
            into = (self.background
                    if threading.current_thread().name.startswith(BACKGROUND_THREAD)
                    else self.spans)
            with self.lock:
                into.append((start, end))

    def mark(self) -> int:
        with self.lock:
            return len(self.spans)

    def since(self, mark: int) -> float:
        with self.lock:
            spans = list(self.spans[mark:])
        return union_length(spans)


def union_length(spans) -> float:
    """Total length of the union of ``(start, end)`` intervals (nested traces overlap)."""
    total, cur_s, cur_e = 0.0, None, None
    for s, e in sorted(spans):
        if cur_e is None or s > cur_e:
            if cur_e is not None:
                total += cur_e - cur_s
            cur_s, cur_e = s, e
        else:
            cur_e = max(cur_e, e)
    if cur_e is not None:
        total += cur_e - cur_s
    return total


_CLOCK: _CompileClock | None = None


def _clock() -> _CompileClock:
    global _CLOCK
    if _CLOCK is None:
        _CLOCK = _CompileClock()
    return _CLOCK
