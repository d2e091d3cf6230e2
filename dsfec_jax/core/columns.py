"""Point-column layouts, defined once: models name the columns they read, data names the columns
it writes, and both import them from here (models and data never import each other).

x, y, z (metres, sensor frame) always come first: pillarization and the boxes rely on it.
"""

# nuScenes radar after ego-motion compensation, 6 sweeps accumulated: what DSFEC reads
NUSCENES_FEATURES = ("x", "y", "z", "rcs", "vx_comp", "vy_comp", "dt")
# View-of-Delft radar .bin rows (N x 7): time is 0 for the current scan, -k for earlier ones
VOD_FEATURES = ("x", "y", "z", "rcs", "v_r", "v_r_comp", "time")
# TJ4DRadSet radar .bin rows (N x 8): radial speed not ego-compensated, power in dB
TJ4D_FEATURES = ("x", "y", "z", "v_r", "range", "power", "alpha", "beta")
