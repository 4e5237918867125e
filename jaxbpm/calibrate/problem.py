"""The problem a calibrator solves: targets, parameters and a forward, with the objective (Qu et al. 2020, Eq. 3).

Weights are normalised to sum 1 and the objective is ``L = sum_k w_k mean((y_k - t_k)^2 / s_k^2)``, ``s_k`` the
target's scale (``|t|`` for a scalar, ``max |t|`` for a vector unless given). A :class:`Problem` counts every solve
(one parameter set on one scene).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxbpm._renamed import batch_size_keyword
from jaxbpm.calibrate.forward import Forward
from jaxbpm.calibrate.space import CalibrationError, ParameterSpace, as_targets

__all__ = ["Problem"]


class Problem:
    """Targets, parameters and a model: evaluates the relative errors and the weighted objective (Qu et al. 2020, Eq. 3)
    and counts the solves (``evaluations``: one parameter set on one scene).

    executor: a :class:`concurrent.futures.Executor` (e.g. Dask's ``Client(...).get_executor()``) on which the runs of
    a model that is not batched (DEM, a plain function with ``pure=False``) are spread: a run set, the perturbed
    runs of a finite-difference gradient (:mod:`jaxbpm.parallel`). retries: how often a run whose worker died is
    submitted again.
    """

    def __init__(self, forward: Forward, targets, space: ParameterSpace, *, executor=None, retries: int = 2):
        from jaxbpm.parallel import check_executor, check_retries

        self.executor, self.retries = check_executor(executor), check_retries(retries)
        if not isinstance(forward, Forward):
            raise CalibrationError(f"forward must be a Forward, got {type(forward).__name__}")
        if not isinstance(space, ParameterSpace):
            raise CalibrationError(f"space must be a ParameterSpace, got {type(space).__name__}")
        self.forward, self.targets, self.space = forward, as_targets(targets), space
        names = [t.name for t in self.targets]
        if len(set(names)) != len(names):
            raise CalibrationError(f"target names must be unique, got {names}")
        for t in self.targets:
            if t.scene not in forward.scenes:
                raise CalibrationError(f"target {t.name!r}: the model has no scene {t.scene!r} "
                                       f"(scenes: {list(forward.scenes)})")
        w = np.asarray([t.weight for t in self.targets], dtype=np.float64)
        self.weights = w / w.sum()
        sizes = [t.size for t in self.targets]
        self.slices = [slice(a, a + s) for a, s in zip(np.cumsum([0] + sizes[:-1]), sizes)]
        self.use_pure = forward.pure is not None and (
            forward.pure_observables is None or all(t.observable in forward.pure_observables
                                                    for t in self.targets))
        self.evaluations = 0
        self.solve_time = 0.0
        self._last = None  # (values, outputs) of the last single point: a repeated point costs no new solve
        #: the observations of the last sets solved one by one (not batched), ``{tuple(values): {scene: obs}}``
        self.observed: dict = {}
        self._sweep_fn = None  # the one-set model function that sharded batches run (see outputs)

    # -------------------------------------------------------------- pieces
    @property
    def n_scenes(self) -> int:
        return len({t.scene for t in self.targets}) if self.use_pure else len(self.forward.scenes)

    @property
    def target_names(self) -> list[str]:
        return [t.name for t in self.targets]

    @property
    def differentiable(self) -> bool:
        return self.use_pure

    def closed_form_applies(self) -> tuple[bool, str]:
        """Whether the closed form applies (bonds-only elasticity, K homogeneous in the bond moduli).

        Returns:
          ``(applies, why)``: why it applies, or why not.
        """
        if not self.forward.homogeneous:
            return False, f"the {self.forward.name} model is not linear in the bond moduli (contacts or walls)"
        if not all(t.elastic for t in self.targets):
            return False, "a target is not an elastic stiffness or Young's modulus"
        if not all(p.key == "bond_E" for p in self.space.parameters):
            return False, "a free parameter is not a bond Young's modulus"
        covered = sum(int(np.size(self.space.base["bond_E"])) if p.index is None else 1
                      for p in self.space.parameters)
        if covered != int(np.size(self.space.base["bond_E"])):
            return False, "some bond moduli are held fixed (K is then not proportional to the free ones)"
        return True, "stiffness is linear in a common factor on the bond moduli (bonds-only elasticity)"

    def _vector(self):
        """The model's target elements ``(values, base) -> [m]`` as a plain function. Called with concrete values (one
        parameter set), the solvers' stiffness functions run the programs ``solve`` compiles, so a calibration after
        a solve of the same sample compiles no solver again."""
        targets, space, pure = self.targets, self.space, self.forward.pure

        def vector(values, base):
            obs = pure(space.to_params(values, base))
            return jnp.concatenate([jnp.reshape(t.extract(obs), (-1,)) for t in targets])

        return vector

    def _compiled(self, what):
        """Jitted pure functions, cached on the model per parameter and target structure: problems that differ only
        in values (targets, initial values, bases) share one compilation."""
        targets, space = self.targets, self.space
        key = (what, space.structure, tuple((t.observable, t.scene, t.at, t.size) for t in targets))
        cache = self.forward._compiled
        if key not in cache:
            vector = self._vector()

            if what == "vector":
                fn = vector
            elif what == "batch":
                fn = jax.vmap(vector, in_axes=(0, None))
            elif what == "jacobian":
                def fn(values, base):
                    return vector(values, base), jax.jacfwd(vector)(values, base)
            else:  # value_and_grad of the loss in z
                def loss_z(z, base, initial, scales, tvals, tscale, wel):
                    y = vector(space.from_z(z, initial, scales), base)
                    return jnp.sum(wel * jnp.square((y - tvals) / tscale)), y

                fn = jax.value_and_grad(loss_z, has_aux=True)
            cache[key] = jax.jit(fn)
        return cache[key]

    def _element_arrays(self):
        tvals = np.concatenate([np.reshape(t.value, -1) for t in self.targets])
        tscale = np.concatenate([np.full(t.size, t.scale) for t in self.targets])
        wel = np.concatenate([np.full(t.size, w / t.size) for t, w in zip(self.targets, self.weights)])
        return tvals, tscale, wel

    # -------------------------------------------------------------- evaluation
    def outputs(self, values_batch, *, batch_size: int | None = None, progress: bool = False,
                on_row: Callable[[int, np.ndarray], None] | None = None, chunk: int | None = None) -> np.ndarray:
        """The forward's values of all target elements for a batch of parameter sets (``vmap`` when pure).

        A forward that is not batched (DEM, a plain function with ``pure=False``) solves the sets one after another, or,
        with an ``executor`` (:class:`Problem`), as separate tasks, one per set and scene (see :mod:`jaxbpm.parallel`).

        Args:
          values_batch: parameter values ``[B, n]``.
          batch_size: for a pure forward, solve at most this many sets in one ``vmap`` (bounds the memory of large
            batches: each vmapped solve holds its own operator and workspace); the last batch is padded so that every
            batch shares one compilation. ``None``: all at once.
          progress: a bar of the sets solved (:mod:`jaxbpm.progress`) where they are solved in parts (batches, or one
            at a time).
          on_row: called ``(index, row)`` as each set of a forward that is not batched finishes (in completion order),
            e.g. to store it.
          chunk: deprecated name of ``batch_size`` (a :class:`DeprecationWarning`); removed in the next release.

        Returns:
          ``[B, m]``.

        Raises:
          CalibrationError: a bad ``batch_size``, a target the forward does not report, a solve that did not
            converge.
          TypeError: both ``batch_size`` and ``chunk``.
        """
        batch_size = batch_size_keyword(batch_size, chunk)
        vb = np.atleast_2d(np.asarray(values_batch, dtype=np.float64))
        if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer))
                                       or batch_size < 1):
            raise CalibrationError(f"batch_size must be a whole number >= 1, got {batch_size!r}")
        if len(vb) == 1 and self._last is not None and np.array_equal(self._last[0], vb[0]):
            return self._last[1][None].copy()
        t0 = time.perf_counter()
        if self.use_pure:
            base = self.space.base
            if len(vb) > 1 and jax.device_count() > 1:
                # several devices (GPUs, or host devices): the batch is sharded over all of them
                from jaxbpm.sweep import sweep

                if self._sweep_fn is None:
                    vector, space_base = self._compiled("vector"), base
                    self._sweep_fn = lambda v: vector(v, space_base)  # one function: sweep compiles it once
                y = np.asarray(sweep(self._sweep_fn, jnp.asarray(vb), batch_size=batch_size))
            elif batch_size is not None and len(vb) > batch_size > 1:
                fn, parts, shown = self._compiled("batch"), [], _bar(progress, len(vb))
                for a in range(0, len(vb), batch_size):
                    part = vb[a:a + batch_size]
                    pad = np.concatenate([part, np.repeat(part[-1:], batch_size - len(part), axis=0)])
                    parts.append(np.asarray(fn(jnp.asarray(pad), base))[:len(part)])
                    shown.update(len(part))
                shown.close()
                y = np.concatenate(parts)
            elif batch_size == 1 and len(vb) > 1:
                fn, shown, rows = self._compiled("vector"), _bar(progress, len(vb)), []
                for v in vb:
                    rows.append(np.asarray(fn(jnp.asarray(v), base)))
                    shown.update(1)
                shown.close()
                y = np.stack(rows)
            elif len(vb) > 1:
                # small batches are padded to a power of two (repeating the last set): the batch sizes of n-point
                # finite differences (n + 1, 2n) then share compilations
                size = 1 << (len(vb) - 1).bit_length() if len(vb) <= 8 else len(vb)
                pad = np.concatenate([vb, np.repeat(vb[-1:], size - len(vb), axis=0)])
                y = np.asarray(self._compiled("batch")(jnp.asarray(pad), base))[:len(vb)]
            else:  # one set: not jitted here (the solvers run their own compiled programs)
                y = np.asarray(self._vector()(jnp.asarray(vb[0]), base))[None]
        else:
            shown = _bar(progress and len(vb) > 1, len(vb))
            if self.executor is not None:
                y = self._spread(vb, shown, on_row)
            else:
                rows = []
                for i, v in enumerate(vb):
                    obs = self.forward.evaluate(self.space.to_params(jnp.asarray(v)))
                    self._observed(v, obs)
                    rows.append(self._row(obs))
                    if on_row is not None:
                        on_row(i, rows[-1])
                    shown.update(1)
                y = np.stack(rows)
            shown.close()
        self.evaluations += len(vb) * self.n_scenes
        self.solve_time += time.perf_counter() - t0
        if len(vb) == 1:
            self._last = (vb[0].copy(), y[0].copy())
        return y

    def _observed(self, values, obs):
        """Keep ``obs`` (a set's observations by scene) for :attr:`observed`, the last 16 sets."""
        self.observed[tuple(np.asarray(values, dtype=np.float64).tolist())] = obs
        while len(self.observed) > 16:
            self.observed.pop(next(iter(self.observed)))

    def _row(self, obs) -> np.ndarray:
        return np.concatenate([np.reshape(np.asarray(t.extract(obs)), (-1,)) for t in self.targets])

    def _spread(self, vb, shown, on_row) -> np.ndarray:
        """The runs of ``vb`` as tasks on ``self.executor`` (one per parameter set and scene), rows in order."""
        from jaxbpm.parallel import run_tasks

        owner, tasks, scenes = [], [], []
        for i, v in enumerate(vb):
            made = self.forward.tasks(self.space.to_params(jnp.asarray(v)))
            if not made:
                raise CalibrationError(f"the {self.forward.name} model cannot be sent to other processes (it is not "
                                       "a solver model nor a plain function): run it without an executor")
            for key, task in made:
                owner.append(i), tasks.append(task), scenes.append(key)
        parts: dict = {}
        rows: list = [None] * len(vb)

        def arrived(k, value):
            i = owner[k]
            got = parts.setdefault(i, {})
            got[scenes[k]] = value
            if len(got) == owner.count(i):
                self._observed(vb[i], got)
                rows[i] = self._row(got)
                if on_row is not None:
                    on_row(i, rows[i])
                shown.update(1)

        run_tasks(self.executor, tasks, on_result=arrived, retries=self.retries)
        return np.stack(rows)

    def jacobian(self, values) -> tuple[np.ndarray, np.ndarray]:
        """Outputs and their Jacobian by forward-mode autodiff (pure forwards only).

        Args:
          values: parameter values ``[n]``.

        Returns:
          ``(outputs [m], jacobian [m, n])``.
        """
        t0 = time.perf_counter()
        y, j = self._compiled("jacobian")(jnp.asarray(values, dtype=jnp.float64), self.space.base)
        self.evaluations += self.n_scenes
        self.solve_time += time.perf_counter() - t0
        return np.asarray(y), np.asarray(j)

    def value_and_grad(self, z) -> tuple[float, np.ndarray, np.ndarray]:
        """Loss, its gradient with respect to ``z`` (reverse-mode autodiff) and the outputs (pure forwards only).

        Args:
          z: the point ``[n]`` in the optimisation variable.

        Returns:
          ``(loss, gradient [n], outputs [m])``.

        Raises:
          CalibrationError: the forward has no pure function for these targets.
        """
        if not self.use_pure:
            raise CalibrationError(f"autodiff gradients need a pure model; the {self.forward.name} model with "
                                   f"targets {self.target_names} has none (use gradient='fd-forward')")
        t0 = time.perf_counter()
        sp = self.space
        (loss, y), g = self._compiled("value_and_grad")(jnp.asarray(z, dtype=jnp.float64), sp.base,
                                                        jnp.asarray(sp.initial), jnp.asarray(sp.scales),
                                                        *map(jnp.asarray, self._element_arrays()))
        self.evaluations += self.n_scenes
        self.solve_time += time.perf_counter() - t0
        return float(loss), np.asarray(g), np.asarray(y)

    # -------------------------------------------------------------- objective
    def errors_of(self, y):
        """Relative errors of all target elements.

        Args:
          y: outputs ``[m]`` (NumPy or JAX).

        Returns:
          ``[m]``: ``(y - t) / s`` per element.
        """
        xp = jnp if isinstance(y, jax.Array) else np
        return xp.concatenate([t.relative_error(y[s]) for t, s in zip(self.targets, self.slices)])

    def target_losses(self, e):
        """Each target's weighted term of the objective.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``: ``w_k mean(e_k^2)`` per target.
        """
        xp = jnp if isinstance(e, jax.Array) else np
        return xp.stack([w * xp.mean(xp.square(e[s])) for w, s in zip(self.weights, self.slices)])

    def loss_of(self, e):
        """The objective (Qu et al. 2020, Eq. 3).

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``L = sum_k w_k mean(e_k^2)``.
        """
        xp = jnp if isinstance(e, jax.Array) else np
        return xp.sum(self.target_losses(e))

    def max_errors(self, e) -> np.ndarray:
        """Each target's largest relative error magnitude.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``.
        """
        e = np.asarray(e)
        return np.array([np.max(np.abs(e[s])) for s in self.slices])

    def signed_errors(self, e) -> dict[str, Any]:
        """The errors by target name.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``{target name: error}``: a float for a scalar target, an array for a vector target.
        """
        e = np.asarray(e)
        return {t.name: (float(e[s][0]) if t.size == 1 else e[s].copy()) for t, s in zip(self.targets, self.slices)}

    def per_target(self, e) -> np.ndarray:
        """One error per target: signed for a scalar target, the largest magnitude for a vector target.

        Args:
          e: relative errors ``[m]``.

        Returns:
          ``[k]``.
        """
        e = np.asarray(e)
        return np.array([float(e[s][0]) if t.size == 1 else float(np.max(np.abs(e[s])))
                         for t, s in zip(self.targets, self.slices)])



def _bar(progress, total):
    """A bar of parameter sets solved (:mod:`jaxbpm.progress`), showing nothing unless ``progress``."""
    from jaxbpm.progress import bar

    return bar("run set", total=total, unit="run", disable=not progress)
