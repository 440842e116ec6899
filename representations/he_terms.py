"""The numbers of He et al.'s model (he_model.py), shared with its drjit kernel
(he_kernel.py), which imports no model module: one definition of each."""

from __future__ import annotations

import math

#: λ of the R, G, B channels in µm (BBM's rgbConfig::wavelength).
WAVELENGTHS_UM = (0.645, 0.526, 0.444)
#: Beyond this u = τ cotθ/(2σ0), erfc(u) and e^{−u²} are 0 in fp64: S = 1, K = 0.
U_MAX = 40.0
HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
INV_SQRT_8PI = 1.0 / math.sqrt(8.0 * math.pi)

# The series' windows (module docstring).
#: integer terms below and above round(m_c)
N_DOWN, N_UP = 37, 56
#: the trapezoid rule where m_c ≥ M_SWITCH and s ≥ S_MIN
M_SWITCH, S_MIN = 38.0, 1.5
#: its nodes, over [m_c − T_LO s, m_c + T_HI s] (the lower end at most m_c − 1)
N_STRIDED, T_LO, T_HI = 27, 7.0, 9.0
#: Stirling's remainder lgamma(m+1) − (m + ½) log m + m − ½ log 2π at m = 1..7 (exact);
#: from m = 8 its asymptotic series (error < 3e-13).
STIRLERR = tuple(math.lgamma(m + 1.0) - (m + 0.5) * math.log(m) + m - HALF_LOG_2PI for m in range(1, 8))
#: elements per block of the windows' (elements × terms) arrays
CHUNK = 1 << 15
#: a log-ratio of neighbouring terms is capped here (never reached with m_c as found: a guard)
LOG_CAP = 80.0
