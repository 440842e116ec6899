"""Scalar float64 port of the MERL reference reader's lookup (Matusik et al., BRDFRead.cpp).

Written independently from the published algorithm, one C++ operation per Python operation
and in the same order, with `math` (the C library's libm) for the transcendental functions,
so that it rounds as a straightforward build of the C++ reader does. It is deliberately
slow and simple: the tests use it as the oracle for `brdfbench.merl.lookup_nearest`.

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


def c_acos(x):
    """C's acos: NaN outside [-1, 1] (rounding can push a unit vector's z a hair past 1)."""
    return math.acos(x) if -1.0 <= x <= 1.0 else math.nan


def c_int(x):
    """C's (int) cast of a double as x86-64 executes it (cvttsd2si): truncation toward zero;
    NaN and out-of-range values give INT_MIN, which the index functions then clamp to 0."""
    if math.isnan(x) or not -2147483649.0 < x < 2147483648.0:
        return -2147483648
    return int(x)


def cross_product(v1, v2):
    return (
        v1[1] * v2[2] - v1[2] * v2[1],
        v1[2] * v2[0] - v1[0] * v2[2],
        v1[0] * v2[1] - v1[1] * v2[0],
    )


def normalize(v):
    length = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / length, v[1] / length, v[2] / length)


def rotate_vector(vector, axis, angle):
    """Rodrigues rotation of `vector` about the unit `axis` by `angle`.

    out = v cos a + axis (axis · v)(1 − cos a) + (axis × v) sin a, accumulated in that order.
    """
    cos_ang = math.cos(angle)
    sin_ang = math.sin(angle)
    out = [vector[0] * cos_ang, vector[1] * cos_ang, vector[2] * cos_ang]
    temp = axis[0] * vector[0] + axis[1] * vector[1] + axis[2] * vector[2]
    temp = temp * (1.0 - cos_ang)
    out[0] += axis[0] * temp
    out[1] += axis[1] * temp
    out[2] += axis[2] * temp
    cross = cross_product(axis, vector)
    out[0] += cross[0] * sin_ang
    out[1] += cross[1] * sin_ang
    out[2] += cross[2] * sin_ang
    return tuple(out)


def direction_from_angles(theta, phi):
    """The reader's (θ, φ) → unit vector step, normalisation included."""
    z = math.cos(theta)
    proj = math.sin(theta)
    return normalize((proj * math.cos(phi), proj * math.sin(phi), z))


def half_diff_from_vectors(vin, vout):
    """std_coords_to_half_diff_coords after its vectors are built: (θh, φh, θd, φd).

    Half vector = normalised (in + out) / 2; θh = acos(hz), φh = atan2(hy, hx); the
    difference vector is `in` rotated by −φh about the normal, then by −θh about the
    binormal (0, 1, 0); θd = acos(dz), φd = atan2(dy, dx) in [−π, π].
    """
    half = normalize(((vin[0] + vout[0]) / 2.0, (vin[1] + vout[1]) / 2.0, (vin[2] + vout[2]) / 2.0))
    theta_half = c_acos(half[2])
    phi_half = math.atan2(half[1], half[0])
    binormal = (0.0, 1.0, 0.0)
    normal = (0.0, 0.0, 1.0)
    temp = rotate_vector(vin, normal, -phi_half)
    diff = rotate_vector(temp, binormal, -theta_half)
    theta_diff = c_acos(diff[2])
    phi_diff = math.atan2(diff[1], diff[0])
    return theta_half, phi_half, theta_diff, phi_diff


def std_coords_to_half_diff_coords(theta_in, phi_in, theta_out, phi_out):
    """The reader's entry point: spherical angles of ωi and ωo → (θh, φh, θd, φd)."""
    return half_diff_from_vectors(direction_from_angles(theta_in, phi_in), direction_from_angles(theta_out, phi_out))


def theta_half_index(theta_half):
    """Square-root warped θh index in [0, 89]."""
    if theta_half <= 0.0:
        return 0
    theta_half_deg = (theta_half / (math.pi / 2.0)) * RES_THETA_H
    temp = theta_half_deg * RES_THETA_H
    temp = math.sqrt(temp)
    index = c_int(temp)
    if index < 0:
        index = 0
    if index >= RES_THETA_H:
        index = RES_THETA_H - 1
    return index


def theta_diff_index(theta_diff):
    """Linear θd index in [0, 89]."""
    index = c_int(theta_diff / (math.pi * 0.5) * RES_THETA_D)
    if index < 0:
        return 0
    if index < RES_THETA_D - 1:
        return index
    return RES_THETA_D - 1


def phi_diff_index(phi_diff):
    """φd index in [0, 179]: reciprocity (φd ~ φd + π) folds a negative φd up by π."""
    if phi_diff < 0.0:
        phi_diff += math.pi
    index = c_int(phi_diff / math.pi * RES_PHI_D / 2)
    if index < 0:
        return 0
    if index < RES_PHI_D // 2 - 1:
        return index
    return RES_PHI_D // 2 - 1


def indices_from_vectors(vin, vout):
    """(θh index, θd index, φd index) of a pair of unit vectors."""
    theta_half, _phi_half, theta_diff, phi_diff = half_diff_from_vectors(vin, vout)
    return theta_half_index(theta_half), theta_diff_index(theta_diff), phi_diff_index(phi_diff)


def flat_index(ih, id_, ip):
    return ip + id_ * (RES_PHI_D // 2) + ih * (RES_PHI_D // 2) * RES_THETA_D


def lookup_from_vectors(brdf, vin, vout):
    """(red, green, blue) BRDF values of a pair of unit vectors; `brdf` is the flat raw array."""
    ind = flat_index(*indices_from_vectors(vin, vout))
    n = RES_THETA_H * RES_THETA_D * RES_PHI_D // 2
    red = float(brdf[ind]) * RED_SCALE
    green = float(brdf[ind + n]) * GREEN_SCALE
    blue = float(brdf[ind + RES_THETA_H * RES_THETA_D * RES_PHI_D]) * BLUE_SCALE
    return red, green, blue


def lookup_brdf_val(brdf, theta_in, phi_in, theta_out, phi_out):
    """The reader's lookup_brdf_val: spherical angles of ωi and ωo → (red, green, blue)."""
    return lookup_from_vectors(brdf, direction_from_angles(theta_in, phi_in), direction_from_angles(theta_out, phi_out))
