# The knob lists the calibration scripts search (`sasmi calibrate --params`), sourced by them:
#     . benchmarks/knob_lists.sh
# the floor knobs of one kind of seabed: geometry, relief, sand waves and a second sediment, gray levels and speckle
FLOOR_KNOBS=sonar.altitude,sonar.near_range,sonar.chip_size,sonar.track_length,sonar.cone_angle,seafloor.albedo,\
seafloor.rms_height,seafloor.correlation_length,seafloor.ripple_amplitude,seafloor.ripple_wavelength,\
seafloor.ripple_direction,seafloor.ripple_sinuosity,seafloor.ripple_sharpness,seafloor.mosaic_contrast,\
seafloor.mosaic_share,seafloor.mosaic_size,seafloor.rocks,seafloor.rock_radius,post.gain,post.tvg_strength,\
post.noise_floor,post.speckle_looks,post.speckle_cell_range,post.speckle_cell_track,post.noise_std,post.gain_swing,\
post.speckle_wander,post.gain.spread,seafloor.albedo.spread,sonar.altitude.spread
# seafloor_mixed's three kinds of seabed (sand waves, rippled sand, two sediments): the geometry, gray levels and
# speckle as FLOOR_KNOBS, the floor's level and relief alike in every kind, each kind's own features and the two
# later kinds' weights against the first's
MIXED_KNOBS=sonar.altitude,sonar.near_range,sonar.chip_size,sonar.track_length,sonar.cone_angle,seafloor.albedo,\
seafloor.rms_height,seafloor.correlation_length,seafloor.rock_radius,seafloor[0].ripple_amplitude,\
seafloor[0].ripple_wavelength,seafloor[0].ripple_direction,seafloor[0].ripple_sinuosity,\
seafloor[0].ripple_sharpness,seafloor[1].weight,seafloor[1].ripple_amplitude,seafloor[1].ripple_wavelength,\
seafloor[1].rocks,seafloor[2].weight,seafloor[2].mosaic_contrast,seafloor[2].mosaic_share,seafloor[2].mosaic_size,\
post.gain,post.tvg_strength,post.noise_floor,post.speckle_looks,post.speckle_cell_range,post.speckle_cell_track,\
post.noise_std,post.gain_swing,post.speckle_wander,post.gain.spread,seafloor.albedo.spread,sonar.altitude.spread
# the default knobs of commit 80abb38 (ripples among them, no track offset) but post.gain_swing, in their order
NO_SWING=sonar.altitude,sonar.near_range,sonar.chip_size,sonar.track_length,sonar.cone_angle,seafloor.albedo,\
seafloor.rms_height,seafloor.correlation_length,seafloor.ripple_amplitude,seafloor.rocks,seafloor.rock_radius,\
post.gain,post.tvg_strength,post.noise_floor,post.speckle_looks,post.speckle_cell_range,post.speckle_cell_track,\
post.noise_std,targets.size,targets.burial,post.gain.spread,seafloor.albedo.spread,sonar.altitude.spread
