"""Layouts shared by the bundle kernels and their callers: the per-pixel geometry row
(``G_*``), the BRDF parameter vector (``B_*``, ``MODEL_*``, ``NORM_*``, the slope-density
data ``TAB_*``/``ORD_*``), the cone sampling schemes (``SCHEME_*``), the phase-2 modes
(``MODE_*``) and output columns (``OUT_*``), and the display correction vector (``MC_*``).
Re-exported by :mod:`pmdsim.kernels.bundle`, where callers read them.
"""

from __future__ import annotations

# --- per-pixel geometry row layout -------------------------------------------------------
G_T = 0  # (M0 - S) . n_m : t = G_T / (o . n_m)
G_A = 1  # b_k . n_m, k = 1..3 (3 entries)
G_U0 = 4  # (S - M0) . e_u / pitch + (W - 1) / 2
G_B = 5  # b_k . e_u / pitch (3)
G_V0 = 8
G_C = 9  # b_k . e_v / pitch (3)
G_X = 12  # i . x, then b_k . x (4): local tangential/x axis
G_Y = 16  # i . y, b_k . y (4)
G_Z = 20  # i . n, b_k . n (4)
G_VALID = 24  # 1.0 where the vision ray hit the surface from the front
G_SIZE = 25

# --- BRDF parameter vector -----------------------------------------------------------------
B_MODEL = 0
B_RHO = 1
B_AX = 2
B_AY = 3
B_NORM = 4
B_SMITH = 5  # Beckmann: 1.0 = Smith shadowing-masking G1(i) G1(o), 0.0 = none
B_SIZE = 6

MODEL_MIRROR = 0
MODEL_WARD = 1
MODEL_BECKMANN = 2  # F D G / (4 cos_i cos_o), D anisotropic Beckmann, F = rho constant
# Micro-facet models with a general slope density (``pmdsim.brdf.slope_density``): F D G /
# (4 cos_i cos_o), D = p(s_x, s_y) / cos^4(theta_h), G Smith-Beckmann with the density's
# equivalent alphas in B_AX/B_AY. Their vectors are longer than B_SIZE: the model's data
# starts at B_TAB.
MODEL_SLOPE_TABLE = 3  # p piecewise constant on a slope grid (separable or joint)
MODEL_SLOPE_ORDERS = 4  # p = sum_k w_k Gaussian(s - s_k(i)): grating orders of a turned surface
B_TAB = 6
# MODEL_SLOPE_TABLE: [x0, dx, nx, y0, dy, ny, separable] then cdf_x (nx + 1); separable:
# cdf_y (ny + 1), density_x (nx), density_y (ny); joint: cdf_y (nx rows of ny + 1),
# density (nx * ny), per unit slope (area).
TAB_X0, TAB_DX, TAB_NX, TAB_Y0, TAB_DY, TAB_NY, TAB_SEP, TAB_DATA = 0, 1, 2, 3, 4, 5, 6, 7
# MODEL_SLOPE_ORDERS: [alpha_x, alpha_y (Gaussian lobe of each order), K] then K pairs
# (q_k, w_k): order k leaves with local direction cosines (-i_x, -i_y + q_k) (q = m lambda / f,
# grating vector along local y) and weight w_k (efficiency x spectral weight).
ORD_AX, ORD_AY, ORD_K, ORD_DATA = 0, 1, 2, 3

NORM_WARD1992 = 0  # the paper: 1 / (4 pi ax ay sqrt(cos_i cos_o))
NORM_DUER2006 = 1  # 1 / (4 pi ax ay cos_i cos_o)
NORM_GEISLER2010 = 2  # |h|^2 / (pi ax ay (h.n)^4)

# --- sampling ----------------------------------------------------------------------------
SCHEME_POLAR = 0  # theta uniform in [0, theta_max]
SCHEME_SOLID_ANGLE = 1  # cos(theta) uniform in [cos(theta_max), 1]

# --- phase-2 modes -------------------------------------------------------------------------
MODE_TABLES = 0  # out[:, 2 + q] = sum f * table_u[q, iu] (q < nu), then table_v rows
MODE_HARMONIC = 1  # out[:, 2 + 2q (+1)] = sum f * cos (sin)(k_q * coord), u freqs then v
MODE_IMAGES = 2  # out[:, 2 + q] = sum f * images[q, iv, iu]
MODE_DOTS = 3  # out[:, 2 + q] = sum f * [-hu <= iu - u0 < hu and -hv <= iv - v0 < hv]
MODE_TRANSPORT = 4  # out_u/out_v/out_f (npix, nrays): the rays themselves

OUT_FTOTAL = 0
OUT_FHIT = 1
#: Ray loops of :func:`render_tile` (Ward, Beckmann) run over a multiple of this many rays
#: (padding rays of weight 0): a ray in a scalar remainder loop costs ~10 vector lanes.
RAY_BLOCK = 16
OUT_FIRST = 2

# --- display geometry and falloff (optional ``mon_corr`` of the render kernels) -----------
MC_GLASS_T = 0  # cover glass thickness, mm (pixels at its back)
MC_GLASS_N = 1  # cover glass refractive index
MC_PITCH = 2  # monitor pixel pitch, mm
MC_UC = 3  # (W - 1) / 2: monitor px of the centre
MC_VC = 4  # (H - 1) / 2
MC_FLAT_N = 5  # n: flatness polynomial h(x, y) = sum c[i, j] x^i y^j, n x n coefficients
MC_FALL_M = 6  # luminance falloff cos(theta)^m (0 = none)
MC_FALL_N = 7  # falloff table size (0 = none): angles (deg, ascending), then factors
MC_MAP_R = 8  # height map rows (0 = none): nodes from monitor row 0 to H - 1
MC_MAP_C = 9  # height map columns: nodes from monitor column 0 to W - 1
MC_COEF = 10  # c[i, j] row-major (mm, x and y in mm from the centre along e_u, e_v), then
#               the falloff table, then the height map row-major (mm)
