"""indepsim: an independent, physically grounded raw-sensor simulator that writes capture sets.

README
======

Purpose
-------
Capture sets with a known truth (``truth.json``) for testing a noise-model calibration on
data that did not come from its own generator. Written from the literature only: EMVA
Standard 1288 Release 4.0 (sec. 2 linear camera model, eq. 1-8; sec. 7 dark current; sec. 8
spatial non-uniformity), A. Abdelhamed, "Noise Modelling for Smartphone Cameras", PhD
dissertation, York University, 2020, chapter 2 (shot, dark-current, read, quantisation
noise, fixed-pattern noise, defects, crosstalk), and J. Janesick, "Photon Transfer", SPIE 2007.
Nothing here imports simcam except the tests, which read the files back through
``simcam.calibration.capture.read_capture_set`` (the input contract) and rawpy.

Physics and units (``sensor.py``)
---------------------------------
Per pixel and frame, electron domain first:

* photo-electrons ``Poisson(flux_e * t)`` (``flux_e`` e-/s/pixel = photons/s x ``qe``); flats are
  uniform at a ``level`` (fraction of the saturation charge), scenes a smooth textured field;
* dark charge ``Poisson(offset_e + rate * t)`` (dark current, hot pixels, amplifier glow);
* charge effects (crosstalk, full-well clip at ``full_well_e``, compressive non-linearity);
* read noise ``read_noise_e`` (e-, pre-gain, Gaussian unless ``heavy_tail_read``), row noise, RTN;
* system gain ``K(ISO) = k_base * ISO / iso_base`` DN/e- (``k_base`` default: the ADC range
  maps onto the full well) times per-channel gains, post-gain noise ``adc_noise_dn`` (DN);
* DN-domain offsets (column FPN, DSNU, periodic pattern, electrical crosstalk), true black level
  (declared ``black_dn`` per 2x2 site, plus ``black_level_offset``);
* ADC of code width ``adc_step_dn`` (or DNL transition table), clip to ``[0, 2^bits - 1]``;
  stuck pixels overwrite codes. Saturation charge = min(full well, ADC range / K).

Input-referred temporal dark noise: ``sigma_d = sqrt(read_noise_e^2 + (adc_noise_dn/K)^2)`` e-.

Effects (``effects.py``; each class docstring gives physics and parameters)
--------------------------------------------------------------------------
Named: row_noise (sigma_e, e-), column_fpn (sigma_dn), dsnu (sigma_dn), prnu (sigma_rel),
hot_pixels (fraction, offset_e, rate_e_per_s), heavy_tail_read (nu, Student-t), quantization
(step_dn), spatial_correlation (coupling, electrical, after read-out), periodic_pattern
(amplitude_dn, period_px, angle_deg, random phase per frame), black_level_offset (offset_dn),
frame_flicker (gain_sigma, offset_sigma_dn), nonlinearity (beta: e/(1+beta e/FW)), channel_gain
(sigma_rel per 2x2 site), dark_current (rate_e_per_s median, log-normal spread), dead_pixels
(fraction, zero photo-response), stuck_pixels (fraction, white_share), adc_dnl (inl_dn, major_dn),
rtn (fraction, amplitude_e, p_high), amp_glow (rate_e_per_s at a corner, length_frac),
charge_crosstalk (fraction to each neighbour, before read-out).

Own ("undeclared_*", truth carries ``family``: time temporal|fixed, support
pixel|row|column|frame|smooth_field|code, mode additive|multiplicative, exposure_dependent):
undeclared_column_temporal, undeclared_gain_drift, undeclared_black_drift,
undeclared_interleaved_adc, undeclared_row_1f, undeclared_pixel_nonlinearity, undeclared_smear.

Every effect's magnitude range is ``Effect.ranges`` (log-uniform for ``Effect.log_params``);
``cases.magnitude_ranges()`` lists them.

Capture sets (``capture.py``)
-----------------------------
``write_capture_set(out_dir, spec, seed)``: per ISO (default 100, 800, 3200) darks at 0.02 s and
2 s x 16 frames, flats at 15 % and 55 % of saturation x 12 frames, one scene x 16 frames (mean
40 % of saturation, peaks ~70-90 %),
128 x 192 pixels, 12-bit RGGB, black 256 DN. Formats: ``dng`` (own writer on tifffile,
``dngwrite.py``; LibRaw refused a 24 x 16 test image, 96 x 64 reads), ``npy`` + ``sequence.yaml``, ``emva``
(EMVA 1288 descriptor + PNGs, monochrome; scenes are not written). Frames are generated one
by one (a 4000 x 3000 frame peaks near 0.7 GB, ~4 s). ``truth.json`` holds the sensor in
physical units (K per ISO, input read noise, saturation), the true black, each effect's
parameters (plus derived truth: site gains, DNL rms, glow corner, mean dark rate) and the
planned sequences (mean e-, photons per pixel). Monochrome DNGs are LinearRaw (rawpy reads
them); simcam's DNG reader refuses LinearRaw, so the monochrome cases use ``npy`` or ``emva``.
An undeclared effect's ``family`` has keys ``time``, ``support``, ``mode``,
``exposure_dependent`` plus ``family_str`` ("temporal;column;additive;exposure_dependent=false").

Command line::

    python -m tests.indepsim.capture --list
    python -m tests.indepsim.capture --case NAME --out DIR [--seed S] [--fmt dng|npy|emva] [--width W --height H]

Cases (``cases.py``)
--------------------
base_s0..base_s3 (no effect, seeds 0-3); alone_<effect> for all 27 effects; pair_<a>__<b>:
14 old+new, 7 new+new, 7 undeclared+named; two triples; specials: 8-bit sensor with sub-code
dark noise (~0.5 DN, with and without DSNU), monochrome npy, monochrome EMVA 1288, GRBG with a
per-channel black level (npy), darks only, flats only, 2-frame sequences, coarse quantisation
on a 16-bit sensor, 14-bit BGGR. Magnitudes are drawn per case from the documented ranges with
``default_rng([seed, crc32(name)])``.

Held-out rule: ``int(sha256(name).hexdigest()[:8], 16) % 10 < 3`` (19 of 71 cases). Loop
developers must not tune on cases with ``held_out=True``.
"""
