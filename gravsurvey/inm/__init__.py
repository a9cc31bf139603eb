"""3D inertial-navigation-method: mechanization, error model, Kalman filter and RTS smoother."""
