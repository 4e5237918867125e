"""The programs JAX traces or compiles inside a block, from its monitoring events (for the DEM's no-recompilation
tests)."""

import contextlib

import jax


@contextlib.contextmanager
def compilations():
    """The programs traced or compiled inside the block: ``(event, function name)`` pairs, appended as they come."""
    seen = []

    def listener(name, duration, **kwargs):
        if name in ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/backend_compile_duration"):
            seen.append((name.rsplit("/", 1)[-1], kwargs.get("fun_name")))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        yield seen
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
