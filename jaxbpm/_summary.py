"""What :meth:`jaxbpm.sample.Sample.summary` reports (importable as ``jaxbpm.sample.SampleSummary``)."""

from __future__ import annotations

import dataclasses

__all__ = ["SampleSummary"]


@dataclasses.dataclass(frozen=True)
class SampleSummary:
    """What :meth:`jaxbpm.sample.Sample.summary` reports; ``str()`` gives a readable table."""

    n_particles: int
    n_bonds: int
    n_materials: int
    bonds_per_material: tuple[int, ...]
    coordination_mean: float
    coordination_min: int
    coordination_max: int
    n_unbonded: int
    n_clusters: int
    largest_cluster: int
    packing_fraction: float
    packing_basis: str
    bbox_lo: tuple[float, float, float]
    bbox_hi: tuple[float, float, float]
    radius_min: float
    radius_mean: float
    radius_max: float
    total_mass: float
    bond_contact: str
    types: tuple[tuple[int, int], ...] = ()

    def __str__(self) -> str:
        lo = ", ".join(f"{v:.4g}" for v in self.bbox_lo)
        hi = ", ".join(f"{v:.4g}" for v in self.bbox_hi)
        lines = [
            f"particles            {self.n_particles}",
            f"bonds                {self.n_bonds}  (per material: {list(self.bonds_per_material)})",
            f"coordination         mean {self.coordination_mean:.3f}  min {self.coordination_min}"
            f"  max {self.coordination_max}",
            f"unbonded particles   {self.n_unbonded}",
            f"clusters             {self.n_clusters}  (largest {self.largest_cluster} particles)",
            f"packing fraction     {self.packing_fraction:.4f}  ({self.packing_basis})",
            f"radius [m]           min {self.radius_min:.4g}  mean {self.radius_mean:.4g}  max {self.radius_max:.4g}",
            f"bounding box [m]     ({lo}) .. ({hi})",
            f"total mass [kg]      {self.total_mass:.4g}",
            f"bonded pairs         contact forces {self.bond_contact}d",
            f"particle types       {', '.join(f'{t}: {c}' for t, c in self.types)}  (type: particles)",
        ]
        return "\n".join(lines)
