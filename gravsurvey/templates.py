"""The commented example config written by ``gravsurvey init``.

Kept valid by tests: ``tests/test_templates.py`` runs it end to end on the sample survey
``sample_data/grid_ros2`` with only its file paths edited.
"""

EXAMPLE_CONFIG = """\
# gravsurvey processing config, written by `gravsurvey init`. Every key: docs/config.md.
# Paths are relative to this file. Edit the input paths; every other value is a default, and
# what the defaults leave open (noise levels, anomaly prior, initial state, attitude, grid
# spacing) comes from each flight's own data. Optional keys are commented out.
survey:
  name: my_survey                  # in every output and its metadata

ellipsoid: WGS84                   # WGS84 | GRS80: heights and normal gravity refer to it

flights:                           # one entry per flight; names unique (letters, digits, _ . -)
  - name: F01
    inputs:
      mcap: F01/F01_ros2.mcap      # one MCAP with IMU, altimeter and GNSS topics, or:
      # csv: {imu: F01/imu.csv, altimeter: F01/altimeter.csv, gnss: F01/gnss.csv}
      # nav: {format: nmea, file: F01/gnss.nmea}  # GNSS from an NMEA or trajectory text file
    # topics: {imu: /imu, altimeter: /altimeter, gnss: /gnss}  # default; else found by schema
    triad: strapdown               # strapdown (body-fixed IMU) | platform (ENU-stabilised)
    # imu_axes: FLU                # FLU | FRD (VectorNav, Xsens, iMAR, NovAtel) | RFU | 3x3 matrix
    # gnss_lever_arm_m: [0, 0, 0]  # antenna from the IMU, m, forward-left-up (not given: found from the track)
    # initial:                     # optional overrides of the state from the data (GNSS
    #   attitude_deg: [...]        # position and velocity, attitude from the alignment):
    #                              # lat_deg, lon_deg, height_m, velocity_enu_mps, attitude_deg
    # tie:                         # base tie: puts the flight on an absolute level, removes drift
    #   base_gravity_mgal: ...     # the base station's absolute gravity, mGal
    #   before: {reading_mgal: ..., time_s: ...}   # still reading at the base, or a window
    #   after: {start_s: ..., stop_s: ...}         # of the log parked there (docs/survey.md)
    # truth: F01/truth.csv         # simulator truth: adds truth_mgal / error_mgal columns
  - name: F02
    inputs:
      mcap: F02/F02_ros2.mcap
    triad: strapdown

model:                             # 3D-INM Kalman/RTS filter (docs/method.md)
  identify: true                   # noise levels and anomaly prior from each flight's data
  # filter_rate_hz: 1.0            # Kalman epochs per second (not given: 1, or 5 for tactical gyros)
  # target_resolution_m: ...       # ask for a resolution instead of the least-error one
  # accel_bias_mps2: 1.0e-3        # datasheet accelerometer bias, m/s^2 (tactical strapdown IMUs)

lines:                             # line segmentation (docs/outputs.md)
  mode: auto                       # auto (straight, level legs) | windows | whole
  # min_line_m: 2000               # shortest line, m; lines/ties/transits by heading

postprocess:
  method: default                  # the smoothed estimate; docs/wavelet.md for the others

# checks:                          # gaps, clocks, GNSS vs IMU, plausibility (docs/reliability.md)
#   max_imu_gap_s: 2.0
#   max_track_deviation_m: 50

levelling:                         # crossover levelling (docs/survey.md)
  enabled: null                    # null: applied when the crossovers over-determine it and show
                                   # significant level errors (F-test); true: always; false: never
  model: constant                  # constant per line | line_trend | flight_trend | flight_constant

grid:                              # levelled lines to a grid (docs/survey.md)
  enabled: null                    # null: when there are >= 2 lines
  method: equivalent_sources       # equivalent_sources (continued to altitude_m) | spline
  # spacing_m: ...                 # default: a quarter of the line spacing
  # altitude_m: ...                # default: the median flight height

output:
  dir: out                         # profiles.csv, .xyz, lines.geojson, grid.nc, summary.json, PNGs
  # epsg: ...                      # projected CRS; default: the UTM zone of the data
"""
