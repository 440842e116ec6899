"""Adversarial direction pairs: the hard cases every representation must survive.

Each family targets one numerical trap: grazing angles up to 89.99°, θh = 0 (mirror
pairs), ωi = ωo (θd = 0), ωi + ωo ≈ 0 (undefined half vector), directions exactly on or
below the horizon, the normal itself, and uniform pairs for coverage.
"""

from __future__ import annotations

import math

import torch

from ..coords import normalize, spherical_to_vector

FAMILIES = ("grazing", "mirror", "identical", "opposite", "below_horizon", "normal", "uniform")
MAX_GRAZING_DEG = 89.99


def _dirs(theta, phi):
    return spherical_to_vector(theta, phi)


def adversarial_pairs(n: int, dtype: torch.dtype = torch.float64, seed: int = 0) -> dict[str, tuple[torch.Tensor, torch.Tensor]]:
    """About n pairs split over FAMILIES, as {family: (wi, wo)} in `dtype` (built in fp64)."""
    g = torch.Generator().manual_seed(seed)
    k = max(1, n // len(FAMILIES))

    def u(*shape):
        return torch.rand(*shape, generator=g, dtype=torch.float64)

    max_theta = math.radians(MAX_GRAZING_DEG)
    phi = lambda: 2 * math.pi * u(k)  # noqa: E731
    families: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}

    # Grazing: polar angles within 1° of the 89.99° limit, including exactly 89.99°.
    t = max_theta - math.radians(1.0) * u(k) ** 4
    t[: max(1, k // 16)] = max_theta
    families["grazing"] = (_dirs(t, phi()), _dirs(max_theta - math.radians(1.0) * u(k), phi()))

    # θh = 0: ωo is ωi mirrored about the normal.
    t, p = max_theta * u(k), phi()
    wi = _dirs(t, p)
    families["mirror"] = (wi, torch.stack((-wi[:, 0], -wi[:, 1], wi[:, 2]), dim=-1))

    # ωi = ωo, including at grazing.
    t = max_theta * u(k) ** 0.25
    wi = _dirs(t, phi())
    families["identical"] = (wi, wi.clone())

    # ωi + ωo ≈ 0: near-opposite grazing directions, both just above the horizon.
    eps = torch.pow(10.0, -7 * u(k))  # 1e-7 .. 1 rad from the horizon
    p = phi()
    wi = _dirs(math.pi / 2 - eps, p)
    wo = _dirs(math.pi / 2 - eps * u(k), p + math.pi + 1e-6 * (u(k) - 0.5))
    families["opposite"] = (wi, wo)

    # On or below the horizon: must evaluate to exactly 0.
    t_bad = math.pi / 2 + (math.pi / 2) * u(k)
    t_bad[: max(1, k // 8)] = math.pi / 2
    wi = _dirs(max_theta * u(k), phi())
    wo = _dirs(t_bad, phi())
    wo[: max(1, k // 8), 2] = 0.0  # exactly on the horizon
    swap = u(k) < 0.5
    families["below_horizon"] = (torch.where(swap[:, None], wo, wi), torch.where(swap[:, None], wi, wo))

    # The normal itself, paired with anything (and with itself).
    normal = torch.zeros(k, 3, dtype=torch.float64)
    normal[:, 2] = 1.0
    wo = _dirs(max_theta * u(k), phi())
    wo[: max(1, k // 8)] = normal[: max(1, k // 8)]
    families["normal"] = (normal, wo)

    # Uniform in solid angle over the hemisphere.
    families["uniform"] = tuple(_dirs(torch.acos(1 - u(k)), phi()) for _ in range(2))  # type: ignore[assignment]

    return {name: (normalize(a).to(dtype), normalize(b).to(dtype)) for name, (a, b) in families.items()}
