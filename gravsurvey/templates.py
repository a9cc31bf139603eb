"""The commented example config written by ``gravsurvey init`` (kept valid by a test)."""

EXAMPLE_CONFIG = """\
# gravsurvey processing config. Every key: docs/config.md. Paths are relative to this file.
survey:
  name: my_survey                  # used in outputs

ellipsoid: WGS84                   # WGS84 | GRS80 (heights and normal gravity refer to it)

flights:
  - name: F01                      # unique; letters, digits, _ . -
    inputs:
      mcap: F01/F01_json.mcap      # one MCAP with IMU, altimeter (and GNSS) topics
      # csv: {imu: F01/imu.csv, altimeter: F01/altimeter.csv, gnss: F01/gnss.csv}
    topics: {imu: /imu, altimeter: /altimeter, gnss: /gnss}
    triad: platform                # platform (ENU-stabilised) | strapdown (body axes)
    # imu_axes: FLU                # strapdown sensor axes: FLU | FRD (VectorNav, Xsens, iMAR, NovAtel) | RFU | 3x3
    # gnss_lever_arm_m: [0, 0, 0]  # antenna from the IMU, m, forward-left-up (strapdown)
    # initial:                     # optional: the first state comes from the data (GNSS position and
    #   attitude_deg: [r, p, h]    # velocity, attitude from the alignment); any key given here
    #                              # (lat_deg, lon_deg, height_m, velocity_enu_mps, attitude_deg)
    #                              # overrides it and is checked against the data
    # truth: F01/truth.csv         # simulator truth: adds truth_mgal / error_mgal columns

model:                             # 3D-INM Kalman filter; defaults are seed 004's values
  filter_rate_hz: 1.0              # Kalman epochs per second (decimated from the IMU rate)
  accel_noise_mps2: 1.0e-3         # horizontal accelerometer white noise, 1 sigma
  gyro_drift_degph: 0.01           # gyro white drift, 1 sigma, deg/h
  gravimeter_lambda_per_s: 0.025   # gravimeter error correlation rate lambda_f3, 1/s
  gravimeter_sigma_mps2: 1.0e-6    # gravimeter error sigma_f3, m/s^2
  anomaly_lambda_per_m: 1.0e-5     # anomaly correlation rate in space lambda_s, 1/m
  anomaly_sigma_mps2: 1.0e-3       # anomaly sigma_s, m/s^2
  altimeter_sigma_m: 1.0           # radial (height) measurement noise, m
  radius_source: altimeter         # altimeter | computed: |q| used in the gravity model

lines:
  mode: auto                       # auto (straight-line detection) | windows | whole

postprocess:
  method: default                  # see docs/wavelet.md for methods and measured accuracy

output:
  dir: out                         # deliverables: profiles.csv, .xyz, .geojson, summary.json, PNGs
  # epsg: 32653                    # projected CRS for easting/northing; default: UTM zone of the data
"""
