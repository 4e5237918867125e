"""Compile once, answer fast: ahead-of-time compiled programs keyed on shapes, and the size classes samples are
padded to.

A :class:`Program` wraps a module-level function in ``jax.jit`` and keeps one compiled executable per signature (the
pytree structure, shapes and dtypes of the arguments, and the static options). A call returns the outputs with the
time spent compiling (zero on a hit) and running (the executable once, to ``block_until_ready``), so a solver reports
``compile_time`` and ``run_time`` without ever running its kernel twice. ``Program.compilations`` counts the misses
(what the tests check: a second solve compiles nothing). With :func:`jaxbpm.enable_compilation_cache` a miss in a new
process is read from JAX's persistent cache instead of being compiled again.

:func:`capacity` and :func:`size_class` give the padded sizes: particle counts round up on a ladder of four steps per
octave (1, 1.25, 1.5, 1.75 times a power of two: at most 25 % padding), and the bonds (contacts) per particle round up
to a multiple of one half, so the samples a generator makes with one set of options (about the same coordination)
share a class when their particle counts do.
"""

from __future__ import annotations

import collections
import contextlib
import math
import time
import weakref
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["Program", "SetupCache", "capacity", "size_class", "SizeClass", "compile_clock", "count_compilations", "put",
           "setup_jit", "strong", "traced"]


def traced(tree) -> bool:
    """Whether any leaf of ``tree`` is a tracer (inside ``jit``, ``grad``, ``vmap``).

    A pure function then traces its body; called with concrete values it can run a compiled program instead.

    Args:
      tree: a pytree.

    Returns:
      True when some leaf is a tracer.
    """
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def strong(tree):
    """Concrete array leaves of fixed dtype (not weakly typed).

    ``2e9``, ``jnp.asarray(2e9)`` and ``np.float64(2e9)`` then give one :class:`Program` signature, so parameters
    in any of these forms share a compiled program.

    Args:
      tree: a pytree of numbers and arrays.

    Returns:
      The same tree with strongly typed array leaves.
    """
    return jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=jnp.asarray(x).dtype), tree)


def put(a, dtype=None) -> jax.Array:
    """A host array (or scalar) on the default device, compiling nothing.

    Unlike ``jnp.asarray``, which builds a small XLA program per shape for most dtypes, this compiles nothing: setup
    code uses it for everything it builds in NumPy.

    Args:
      a: a NumPy array or scalar.
      dtype: the dtype on the device; default ``a``'s.

    Returns:
      The device array.
    """
    return jax.device_put(np.asarray(a, dtype))


def capacity(count: int, minimum: int = 8) -> int:
    """The next size on the capacity ladder.

    Args:
      count: the size needed.
      minimum: the smallest size returned.

    Returns:
      The smallest ``m * 2**e`` (``m`` in 4, 5, 6, 7) that is at least ``count`` and ``minimum``.
    """
    count = max(int(count), int(minimum), 1)
    e = max(math.ceil(math.log2(count)) - 3, 0)
    while True:
        for m in (4, 5, 6, 7, 8):
            if m * 2 ** e >= count:
                return m * 2 ** e
        e += 1


class SizeClass(tuple):
    """``(particles, bonds, contacts)`` capacities of a padded sample."""

    __slots__ = ()

    def __new__(cls, particles: int, bonds: int, contacts: int = 0):
        return super().__new__(cls, (int(particles), int(bonds), int(contacts)))

    particles = property(lambda self: self[0])
    bonds = property(lambda self: self[1])
    contacts = property(lambda self: self[2])


def _per_particle(count: int, n: int, n_cap: int) -> int:
    """Room for ``count`` items on ``n`` particles padded to ``n_cap``: their count per particle with 0.05 to spare,
    rounded up to a quarter, times ``n_cap`` (and one spare slot at least)."""
    if count == 0:
        return 0
    ratio = math.ceil(4.0 * (count / max(n, 1) + 0.05)) / 4.0
    return max(int(math.ceil(ratio * n_cap)), count + 1)


# the size classes handed out in this process, per particle capacity: a sample that fits one of them (at most 25 %
# larger than the class it would get on its own) reuses it, so that samples whose bond count per particle straddles
# a step of the ladder still share their programs
_classes: dict[int, set] = collections.defaultdict(set)


def size_class(n_particles: int, n_bonds: int, n_contacts: int = 0) -> SizeClass:
    """The padded capacities of a sample: particles on the :func:`capacity` ladder (two spare particles at least,
    which padding bonds connect to); bonds and contacts at the particles' capacity times their count per particle
    with 0.05 to spare, rounded up to a quarter -- or the smallest class already handed out in this process for that
    particle capacity which has room for them and is at most 25 % larger.

    Args:
      n_particles: the sample's particles.
      n_bonds: its bonds.
      n_contacts: its contact candidates.

    Returns:
      ``SizeClass(particles, bonds, contacts)`` capacities.
    """
    n_cap = capacity(n_particles + 2)
    own = SizeClass(n_cap, _per_particle(n_bonds, n_particles, n_cap),
                    _per_particle(n_contacts, n_particles, n_cap))
    fits = [c for c in _classes[n_cap]
            if n_bonds < c.bonds <= 1.25 * own.bonds or (n_bonds == 0 and c.bonds == 0)
            if n_contacts < c.contacts <= 1.25 * own.contacts or (n_contacts == 0 and c.contacts == 0)]
    if fits:
        return min(fits, key=lambda c: (c.bonds, c.contacts))
    _classes[n_cap].add(own)
    return own


def _signature(args, static) -> tuple:
    leaves, treedef = jax.tree_util.tree_flatten(args)
    shapes = tuple((x.shape, x.dtype, getattr(x, "weak_type", False)) if hasattr(x, "dtype") else type(x)
                   for x in leaves)
    return treedef, shapes, tuple(sorted(static.items())), jax.config.jax_enable_x64


# priming stops after an execution that took longer than this [s]: priming is for millisecond-long programs (each
# primed execution of a long one adds its run time to the compile time)
_PRIME_LIMIT = 0.05
# ... and is skipped when the arguments hold more than this many bytes: such a program does not run in milliseconds,
# and a primed execution would double the wall time of its first call
_PRIME_BYTES = 1 << 26


def _nbytes(args) -> int:
    return sum(int(getattr(x, "nbytes", 0)) for x in jax.tree_util.tree_leaves(args))


# every Program alive, so that their executables can be dropped together (release_executables)
_PROGRAMS: weakref.WeakSet = weakref.WeakSet()


def memory_mappings() -> int:
    """The memory mappings this process holds (lines of Linux's ``/proc/self/maps``); 0 where there is no such file.

    Returns:
      The count, to compare with ``vm.max_map_count`` (see :func:`release_executables`).
    """
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return 0


def release_executables() -> None:
    """Drop every compiled executable this process holds: those of jaxbpm's programs and JAX's own caches.

    Each executable XLA's CPU backend loads keeps a dozen or more memory mappings (one per compiled kernel part)
    until it is dropped, and Linux limits a process to ``vm.max_map_count`` of them (65,530 by default). A process
    that compiles thousands of programs and keeps them all (a long test session, a sweep over many sample sizes)
    reaches that limit, and XLA's next compilation then fails inside the compiler. Programs compile again on their
    next call (or are read from the persistent compilation cache where it is enabled).
    """
    for program in list(_PROGRAMS):
        program._compiled.clear()
    jax.clear_caches()


class Program:
    """A jitted function compiled ahead of time once per argument signature.

    ``Program(fn, static_argnames=(...))(*args, **static)`` returns ``(outputs, compile_time, run_time)`` [s]:
    ``compile_time`` is the tracing, lowering and compilation of a new signature (0 when it was compiled before in this
    process), ``run_time`` one execution until its outputs are ready. ``compilations`` counts the signatures compiled;
    ``maxsize`` executables are kept (least recently used dropped).

    ``prime=k`` (for programs that run in milliseconds) executes a new executable ``k`` times on the arguments it was
    compiled for, counted as compile time. The first executions of a program after its compilation fault its scratch
    memory in page by page: glibc's malloc hands that memory back to the system after each of the first two
    executions (the first from its own mapping, the second when the compiler's freed memory is trimmed with it) and
    keeps it from the third on, so that a millisecond-long program's second and third calls would be slower than its
    steady run. Priming stops after an execution longer than 50 ms and is skipped for arguments over 64 MiB (a large
    sample, whose run is not dominated by its page faults).
    """

    def __init__(self, fn: Callable, static_argnames: tuple[str, ...] = (), maxsize: int = 32, prime: int = 0):
        self.fn = fn
        self.prime = int(prime)
        self.static_argnames = tuple(static_argnames)
        self._jit = jax.jit(fn, static_argnames=self.static_argnames)
        self._compiled: collections.OrderedDict = collections.OrderedDict()
        self.maxsize = maxsize
        self.compilations = 0
        _PROGRAMS.add(self)
        self.__name__ = getattr(fn, "__name__", "program")
        self.__doc__ = fn.__doc__

    def compiled(self, *args, **static) -> tuple[Any, float]:
        """The executable for these arguments, compiled when new.

        Args:
          *args: the arguments (their shapes and dtypes make the signature).
          **static: the static arguments.

        Returns:
          ``(executable, compile_time)`` [s]; 0 when it was there.
        """
        unknown = set(static) - set(self.static_argnames)
        if unknown:
            raise TypeError(f"{self.__name__}: unknown static options {sorted(unknown)}")
        key = _signature(args, static)
        exe = self._compiled.get(key)
        if exe is not None:
            self._compiled.move_to_end(key)
            return exe, 0.0
        tc = time.perf_counter()
        exe = self._jit.lower(*args, **static).compile()
        for _ in range(self.prime if _nbytes(args) <= _PRIME_BYTES else 0):
            tp = time.perf_counter()
            jax.block_until_ready(exe(*args))
            if time.perf_counter() - tp > _PRIME_LIMIT:  # a long run: its page faults are a small part of it
                break
        compile_time = time.perf_counter() - tc
        self.compilations += 1
        self._compiled[key] = exe
        if len(self._compiled) > self.maxsize:
            self._compiled.popitem(last=False)
        return exe, compile_time

    def __call__(self, *args, **static):
        exe, compile_time = self.compiled(*args, **static)
        tr = time.perf_counter()
        out = jax.block_until_ready(exe(*args))
        return out, compile_time, time.perf_counter() - tr

    def jit(self, *args, **static):
        """The plain jitted function, for use inside other traced code (``grad``, ``vmap``).

        Args:
          *args: the arguments.
          **static: the static arguments.

        Returns:
          The function's outputs.
        """
        return self._jit(*args, **static)

    def clear(self) -> None:
        """Drop the compiled executables."""
        self._compiled.clear()


# XLA's quick compiler settings: no LLVM optimisation, the older loop emitters for fusions. A setup program (the bond
# law's Jacobians, the preconditioner's parts, the time-step estimate) compiles several times faster and runs a few
# times slower: for small samples, far less compilation for a little more run time
QUICK_OPTIONS = {"xla_backend_optimization_level": 0, "xla_cpu_use_fusion_emitters": False}
_quick_options: dict | None = None


def quick_options() -> dict:
    """The :data:`QUICK_OPTIONS` that this jaxlib's CPU compiler knows (jaxlib 0.11 removed the older fusion
    emitters and, with them, ``xla_cpu_use_fusion_emitters``: an option it does not know fails the compilation).
    Each option is tried once per process on a one-line program.

    Returns:
      ``{option: value}``, the known subset of :data:`QUICK_OPTIONS`.
    """
    global _quick_options
    if _quick_options is None:
        known = {}
        for name, value in QUICK_OPTIONS.items():
            try:
                jax.jit(lambda x: x + 1, compiler_options={name: value}).lower(np.float32(0)).compile()
            except Exception:  # noqa: BLE001 -- an option this compiler does not have
                continue
            known[name] = value
        _quick_options = known
    return _quick_options
QUICK_ROWS = 1 << 15
"""Setup programs (:func:`setup_jit`) whose arguments have at most this many rows (bonds, particles) compile with
:data:`QUICK_OPTIONS` on the CPU; at 32k bonds (about 10k particles) the slower run still costs less than the
compilation it saves. ``0`` turns the quick settings off."""


class SetupJit:
    """A jitted function for code that runs once per sample (its setup: Jacobians at rest, preconditioner parts, a
    time-step estimate), compiled with XLA's quick settings (:data:`QUICK_OPTIONS`) when its arguments are small
    (no array with more than :data:`QUICK_ROWS` rows) and the backend is the CPU, with the full optimisation
    otherwise. Such a program runs once per sample, so on a small sample its compilation is nearly all of its cost;
    the run time of a solver's own programs (called again and again) is never traded for compile time. Inside a
    trace (``jit``, ``grad``, ``vmap``) it is the plain jitted function."""

    def __init__(self, fn: Callable, static_argnames: tuple[str, ...] = ()):
        self.fn = fn
        self._full = jax.jit(fn, static_argnames=static_argnames)
        self._static = static_argnames
        self._quick_jit = None
        self.__name__ = getattr(fn, "__name__", "setup")
        self.__doc__ = fn.__doc__
        self.__wrapped__ = fn

    def quick(self, *args) -> bool:
        """Whether a call on ``args`` compiles with the quick settings.

        Args:
          *args: the arguments (their largest row count decides, see :data:`QUICK_ROWS`).

        Returns:
          True on the CPU for small arguments.
        """
        if QUICK_ROWS <= 0 or traced(args) or jax.default_backend() != "cpu":
            return False
        return all(np.ndim(x) == 0 or np.shape(x)[0] <= QUICK_ROWS for x in jax.tree_util.tree_leaves(args))

    @property
    def _quick(self):
        if self._quick_jit is None:
            self._quick_jit = jax.jit(self.fn, static_argnames=self._static, compiler_options=quick_options())
        return self._quick_jit

    def __call__(self, *args, **static):
        return (self._quick if self.quick(*args) else self._full)(*args, **static)


def setup_jit(fn: Callable | None = None, *, static_argnames: tuple[str, ...] = ()):
    """:class:`SetupJit` of ``fn``; a decorator, with or without ``static_argnames``.

    Args:
      fn: the setup function; ``None`` when used as ``@setup_jit(static_argnames=...)``.
      static_argnames: its static arguments.

    Returns:
      The :class:`SetupJit`, or a decorator that makes one.
    """
    if fn is None:
        return lambda f: SetupJit(f, tuple(static_argnames) if not isinstance(static_argnames, str)
                                  else (static_argnames,))
    return SetupJit(fn, tuple(static_argnames) if not isinstance(static_argnames, str) else (static_argnames,))


def hashable(value) -> bool:
    """Whether ``value`` can be part of a cache key.

    Args:
      value: anything.

    Returns:
      True when ``hash(value)`` works.
    """
    try:
        hash(value)
    except TypeError:
        return False
    return True


def content_key(value):
    """A hashable stand-in for ``value`` that two equal values share: arrays by dtype, shape and a digest of their
    bytes (as JAX keys its compilation cache), dataclasses (scenes) by type and fields, sequences and mappings by
    their items.

    Args:
      value: a cache key, or part of one.

    Returns:
      A hashable value, or ``None`` where some part of ``value`` neither hashes nor is one of the above.
    """
    import dataclasses
    import hashlib

    if isinstance(value, (np.ndarray, jax.Array)):
        arr = np.ascontiguousarray(np.asarray(value))
        return ("array", arr.dtype.str, arr.shape, hashlib.sha1(arr.tobytes()).hexdigest())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        parts = [(f.name, getattr(value, f.name)) for f in dataclasses.fields(value)]
        head = type(value)
    elif isinstance(value, (list, tuple)):
        parts, head = list(enumerate(value)), type(value).__name__
    elif isinstance(value, dict):
        parts, head = sorted(((repr(k), v) for k, v in value.items()), key=lambda kv: kv[0]), "dict"
    else:
        return value if hashable(value) else None
    keyed = []
    for name, part in parts:
        if not hashable(part):
            part = content_key(part)
            if part is None:
                return None
        keyed.append((name, part))
    return (head, tuple(keyed))


_OWNER_KEYS: dict = {}  # id(owner) -> (weak reference to it, its key): an owner's content is digested once


def _owner_key(owner) -> tuple:
    """``("content", key)`` for a dataclass owner with a content key (a sample), else ``("id", id(owner))``."""
    import dataclasses

    hit = _OWNER_KEYS.get(id(owner))
    if hit is not None and hit[0]() is owner:
        return hit[1]
    content = content_key(owner) if dataclasses.is_dataclass(owner) else None
    who = ("id", id(owner)) if content is None else ("content", content)
    _OWNER_KEYS[id(owner)] = (weakref.ref(owner), who)
    while len(_OWNER_KEYS) > 64:
        _OWNER_KEYS.pop(next(iter(_OWNER_KEYS)))
    return who


class SetupCache:
    """The last ``maxsize`` setups (estimators, bond geometry, preconditioner parts: everything a solver builds from a
    sample before it runs) by sample object and options, so that solving the same sample again (other parameters, a
    calibration loop) costs the kernel alone. A :class:`~jaxbpm.Sample` is immutable; an entry lives no longer than
    its sample (held by a weak reference)."""

    def __init__(self, maxsize: int = 4):
        self.maxsize = maxsize
        self._items: collections.OrderedDict = collections.OrderedDict()
        self.builds = 0

    def get(self, owner, key, build: Callable[[], Any]):
        """The setup of ``owner`` under ``key`` (options), built by ``build()`` when absent. An owner that is a
        dataclass of arrays (a :class:`~jaxbpm.Sample`) is known by its content, so that the same sample loaded again
        finds its setup; any other owner by its identity. A key that does not
        hash (a scene holding NumPy masks) is keyed by its content (:func:`content_key`), or built every time where it
        has none. A setup built in float64 is not one for float32 (and the other way round): JAX's
        precision is part of the key.

        Args:
          owner: the object the setup belongs to (a sample; other objects are held weakly).
          key: the options the setup depends on.
          build: makes the setup.

        Returns:
          The setup, computed: its arrays are ready (JAX dispatches work asynchronously; a setup still being computed
          would be paid, and timed, by the first program that reads it).
        """
        key = key if hashable(key) else content_key(key)
        if key is None:  # (some part neither hashes nor has a content to key by)
            self.builds += 1
            return build()
        who = _owner_key(owner)
        k = (who, bool(jax.config.jax_enable_x64), key)
        hit = self._items.get(k)
        if hit is not None and (who[0] == "content" or hit[0]() is owner):
            self._items.move_to_end(k)
            return hit[1]
        value = _ready(build())
        self.builds += 1
        self._items[k] = (weakref.ref(owner), value)
        while len(self._items) > self.maxsize:
            self._items.popitem(last=False)
        return value

    def clear(self) -> None:
        """Drop every cached setup."""
        self._items.clear()


def _ready(value, depth: int = 0):
    """``value`` once every JAX array in it (a pytree, a dataclass, a mapping, a sequence, an object's attributes; a
    few levels deep) is computed."""
    import dataclasses

    if isinstance(value, jax.Array):
        value.block_until_ready()
    elif depth < 4:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            parts = [getattr(value, f.name, None) for f in dataclasses.fields(value)]
        elif isinstance(value, dict):
            parts = list(value.values())
        elif isinstance(value, (list, tuple)):
            parts = list(value)
        else:
            parts = list(getattr(value, "__dict__", {}).values())
        for part in parts:
            _ready(part, depth + 1)
    return value


_LOWERING_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
# what JAX spends to have a program ready: tracing, lowering, compiling or reading it from the persistent cache
_COMPILE_EVENTS = ("/jax/core/compile/jaxpr_trace_duration", _LOWERING_EVENT,
                   "/jax/core/compile/backend_compile_duration", "/jax/compilation_cache/cache_retrieval_time_sec")
_clocks: list = []
_listening = False


class CompileClock:
    """What :func:`compile_clock` measured: ``count`` programs lowered, ``seconds`` spent tracing, lowering,
    compiling or reading programs from the persistent cache (the time those steps cover: a trace nested in another,
    as a jitted function's inside the function that calls it, counts once)."""

    __slots__ = ("count", "_spans")

    def __init__(self):
        self.count, self._spans = 0, []

    def add(self, start: float, end: float) -> None:
        """Add a step that ran from ``start`` to ``end`` (merged with the steps it overlaps).

        Args:
          start: its start [s, ``time.perf_counter``].
          end: its end.
        """
        keep = []
        for a, b in self._spans:
            if b < start or a > end:
                keep.append((a, b))
            else:
                start, end = min(a, start), max(b, end)
        keep.append((start, end))
        self._spans = keep

    @property
    def seconds(self) -> float:
        """The time covered by the steps [s], overlaps counted once."""
        return float(sum(b - a for a, b in self._spans))

    def __getitem__(self, index):  # ``n[0]``: the count, as count_compilations() gives it
        return (self.count, self.seconds)[index]


def _on_event(name, duration, **kwargs):
    if name in _COMPILE_EVENTS:
        end = time.perf_counter()  # the event comes when the step ends
        for c in _clocks:
            c.add(end - duration, end)
            c.count += name == _LOWERING_EVENT


@contextlib.contextmanager
def compile_clock():
    """Count the XLA programs JAX builds inside the ``with`` block (jitted functions and eager operations alike; one
    read from the persistent compilation cache counts too, one held in memory does not) and the time they took::

        with compile_clock() as c:
            jaxbpm.solve(sample, scene, method="ste")
        print(c.count, c.seconds)

    The solvers use it to report the compilation inside their setup as compile time.

    Returns:
      A context manager giving a :class:`CompileClock`.
    """
    global _listening
    if not _listening:
        from jax import monitoring

        monitoring.register_event_duration_secs_listener(_on_event)
        _listening = True
    clock = CompileClock()
    _clocks.append(clock)
    try:
        yield clock
    finally:
        _clocks.remove(clock)


count_compilations = compile_clock
