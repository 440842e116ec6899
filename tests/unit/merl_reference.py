"""Test oracle: the MERL reference reader's lookup (Matusik et al., BRDFRead.cpp) in float64.

Written from the reader's published source, one C operation per Python operation and in
the same order, with `math` (which calls the C library's libm, as a build of the reader
does) for every transcendental function. Plain operations round as a build without FMA
contraction (the x86-64 default). Scalar and deliberately simple: slow, but nothing in it
depends on a vectorised library's rounding.

The reader takes angles: `std_coords_to_half_diff_coords(θi, φi, θo, φo)` and
`lookup_brdf_val(brdf, θi, φi, θo, φo)` are its two entry points. From the angles it builds
two vectors (`reader_vector`: sin θ cos φ, sin θ sin φ, cos θ) and uses them twice, which
is the step a port can easily get wrong: their plain sum, normalised, is the half vector,
while a normalised copy of the incoming one is what it rotates into the half vector's
frame. `half_diff_from_vectors(in_vec, out_vec)` starts the same arithmetic at those two
vectors; it is what the reader computes for angles whose vectors are exactly `in_vec` and
`out_vec`. For vectors made any other way, `angles_of_vector` gives the angles to call the
reader with: θ = atan2(hypot(x, y), z), φ = atan2(y, x).

The reader's flat array `brdf` holds the file's float64 values after the 12-byte header:
channel-major (all red, then green, then blue), each channel laid out as
[θh index][θd index][φd index] with 90 × 90 × 180 cells.
"""

from __future__ import annotations

import math

RES_THETA_H = 90
RES_THETA_D = 90
RES_PHI_D = 360  # the reader's BRDF_SAMPLING_RES_PHI_D; the table stores half of it (180)

RED_SCALE = 1.0 / 1500.0
GREEN_SCALE = 1.15 / 1500.0
BLUE_SCALE = 1.66 / 1500.0

INT_MIN = -2147483648


def c_acos(x):
    """C's acos: NaN outside [-1, 1] (a rounded unit vector's z can exceed 1 by an ulp)."""
    return math.acos(x) if -1.0 <= x <= 1.0 else math.nan


def c_int(x):
    """C's (int) of a double as x86-64 executes it (cvttsd2si): truncation toward zero;
    NaN and out-of-range values give INT_MIN, which the index functions then clamp to 0."""
    if math.isnan(x) or not -2147483649.0 < x < 2147483648.0:
        return INT_MIN
    return int(x)


def cross_product(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def c_div(a, b):
    """C's a / b: IEEE division, so a zero divisor gives ±inf or NaN instead of raising."""
    if b == 0.0:
        return math.nan if a == 0.0 or math.isnan(a) else math.copysign(math.inf, a) * math.copysign(1.0, b)
    return a / b


def normalize(v):
    """v / |v|, the norm as sqrt(x² + y² + z²) summed left to right (0/0 gives NaN, as in C)."""
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (c_div(v[0], n), c_div(v[1], n), c_div(v[2], n))


def rotate_vector(v, axis, angle):
    """Rodrigues' rotation of v about the unit `axis`, as the reader accumulates it:
    v cos a, then + axis (axis · v)(1 − cos a), then + (axis × v) sin a."""
    c = math.cos(angle)
    s = math.sin(angle)
    x, y, z = v[0] * c, v[1] * c, v[2] * c
    k = axis[0] * v[0] + axis[1] * v[1] + axis[2] * v[2]
    k = k * (1.0 - c)
    x, y, z = x + axis[0] * k, y + axis[1] * k, z + axis[2] * k
    w = cross_product(axis, v)
    return (x + w[0] * s, y + w[1] * s, z + w[2] * s)


def reader_vector(theta, phi):
    """The vector the reader builds from (θ, φ), before it normalises a copy of it."""
    r = math.sin(theta)
    return (r * math.cos(phi), r * math.sin(phi), math.cos(theta))


def angles_of_vector(v):
    """(θ, φ) of a vector, to feed the reader with directions made elsewhere."""
    return math.atan2(math.hypot(v[0], v[1]), v[2]), math.atan2(v[1], v[0])


NORMAL = (0.0, 0.0, 1.0)
BINORMAL = (0.0, 1.0, 0.0)


def half_diff_from_vectors(in_vec, out_vec):
    """(θh, φh, θd, φd) from the reader's two vectors, as std_coords_to_half_diff_coords
    goes on once it has built them: θh, θd by acos, φh, φd by atan2 (φd in [−π, π])."""
    vin = normalize(in_vec)
    half = normalize(((in_vec[0] + out_vec[0]) / 2.0, (in_vec[1] + out_vec[1]) / 2.0, (in_vec[2] + out_vec[2]) / 2.0))
    theta_half = c_acos(half[2])
    phi_half = math.atan2(half[1], half[0])
    tmp = rotate_vector(vin, NORMAL, -phi_half)
    diff = rotate_vector(tmp, BINORMAL, -theta_half)
    return theta_half, phi_half, c_acos(diff[2]), math.atan2(diff[1], diff[0])


def std_coords_to_half_diff_coords(theta_in, phi_in, theta_out, phi_out):
    """The reader's conversion: spherical angles of ωi and ωo → (θh, φh, θd, φd)."""
    return half_diff_from_vectors(reader_vector(theta_in, phi_in), reader_vector(theta_out, phi_out))


def _clamp(index, last):
    return 0 if index < 0 else min(index, last)


def theta_half_index(theta_half):
    """Square-root warped θh index in [0, 89]; θh <= 0 gives 0 (NaN goes on, cast to 0)."""
    if theta_half <= 0.0:
        return 0
    t = (theta_half / (math.pi / 2.0)) * RES_THETA_H
    t = math.sqrt(t * RES_THETA_H)
    return _clamp(c_int(t), RES_THETA_H - 1)


def theta_diff_index(theta_diff):
    """Linear θd index in [0, 89]."""
    return _clamp(c_int(theta_diff / (math.pi * 0.5) * RES_THETA_D), RES_THETA_D - 1)


def phi_diff_index(phi_diff):
    """φd index in [0, 179]: reciprocity (φd ~ φd + π) moves a negative φd, −π included, up by π."""
    if phi_diff < 0.0:
        phi_diff += math.pi
    return _clamp(c_int(phi_diff / math.pi * RES_PHI_D / 2), RES_PHI_D // 2 - 1)


def cell_coordinates(theta_half, theta_diff, phi_diff):
    """The three values the reader truncates to its indices (before clamping), in cells:
    a pair lies within x cells of an edge where one of them is within x of an integer."""
    if phi_diff < 0.0:
        phi_diff += math.pi
    u_h = math.sqrt((theta_half / (math.pi / 2.0)) * RES_THETA_H * RES_THETA_H) if theta_half > 0.0 else 0.0
    return u_h, theta_diff / (math.pi * 0.5) * RES_THETA_D, phi_diff / math.pi * RES_PHI_D / 2


def indices(theta_half, theta_diff, phi_diff):
    return theta_half_index(theta_half), theta_diff_index(theta_diff), phi_diff_index(phi_diff)


def indices_from_angles(theta_in, phi_in, theta_out, phi_out):
    """(θh, θd, φd) indices of the reader's lookup at these angles."""
    th, _, td, pd = std_coords_to_half_diff_coords(theta_in, phi_in, theta_out, phi_out)
    return indices(th, td, pd)


def indices_from_vectors(in_vec, out_vec):
    """(θh, θd, φd) indices from the reader's two vectors (see `half_diff_from_vectors`)."""
    th, _, td, pd = half_diff_from_vectors(in_vec, out_vec)
    return indices(th, td, pd)


def flat_index(ih, id_, ip):
    return ip + id_ * (RES_PHI_D // 2) + ih * (RES_PHI_D // 2) * RES_THETA_D


def _values(brdf, ind):
    n = RES_THETA_H * RES_THETA_D * RES_PHI_D // 2
    return (float(brdf[ind]) * RED_SCALE, float(brdf[ind + n]) * GREEN_SCALE,
            float(brdf[ind + RES_THETA_H * RES_THETA_D * RES_PHI_D]) * BLUE_SCALE)


def lookup_brdf_val(brdf, theta_in, phi_in, theta_out, phi_out):
    """The reader's lookup: spherical angles of ωi and ωo → (red, green, blue)."""
    return _values(brdf, flat_index(*indices_from_angles(theta_in, phi_in, theta_out, phi_out)))


def lookup_from_vectors(brdf, in_vec, out_vec):
    """(red, green, blue) from the reader's two vectors; `brdf` is the flat raw array."""
    return _values(brdf, flat_index(*indices_from_vectors(in_vec, out_vec)))
