"""gravsurvey: airborne gravimetry by 3D inertial-navigation-method Kalman dynamic inversion."""

__version__ = "0.1.0"
