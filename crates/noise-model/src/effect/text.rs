//! The words of the effect library: each effect's Allan-plot signature and a paragraph on its
//! physics.
use super::Effect;

impl Effect {
    /// How the effect shows on the Allan plot — the signature used in the diagnosis text.
    pub fn signature(&self) -> &str {
        match self {
            Effect::Quantization => "slope −1 in σ(τ) at the shortest τ (phase/angle white noise)",
            Effect::White => "slope −½ in σ(τ); N is read at τ = 1 s",
            Effect::Flicker => "a flat floor, slope 0; the minimum of σ(τ) ≈ 0.664·B",
            Effect::RateRandomWalk => "slope +½ in σ(τ) at long τ; K is read at τ = 3 s",
            Effect::RateRamp => "slope +1 in σ(τ) at the longest τ; R is read at τ = √2 s",
            Effect::Markov => {
                "a bump: slope +½ for τ ≪ τ_c, a maximum σ ≈ 0.62·sigma at τ ≈ 1.89·τ_c, \
                 slope −½ for τ ≫ τ_c"
            }
            Effect::Sinusoid => {
                "an oscillation with envelope slope −1, a first maximum σ ≈ 0.725·A at \
                 τ ≈ 0.371/f and nulls at τ = k/f; a line at f in the PSD"
            }
            Effect::Resolution => {
                "a white floor of LSB²/12 per sample (slope −½), known from the spacing of the \
                 values: it sets how far below the white line the shortest τ can go"
            }
            Effect::BiasStep => {
                "slope +½ at long τ like a rate random walk (σ² ≈ Δ²τ/3T for a step Δ in a \
                 record of length T), but one large jump in the time series instead of many small \
                 ones; the robust Allan variance does not see it"
            }
            Effect::Temperature => {
                "slope +½ to +1 at long τ, following the Allan variance of the temperature \
                 column itself; in the time series the bias tracks the temperature"
            }
            Effect::Drift { .. } => {
                "slope +½ to +1 at long τ (like a ramp where the drift is monotone, bending over \
                 where it turns), reaching its largest values at τ of the order of the record; in \
                 the time series a slow, smooth wander of the bias that neither one step, one \
                 exponential nor the temperature describes"
            }
            Effect::Lowpass | Effect::Lowpass2 => {
                "σ(τ) below the white line at τ ≲ 1/(2πf_c) (slope +½ at the shortest τ for one \
                 pole, steeper for two), joining it for τ ≫ 1/f_c; the PSD falls off above f_c"
            }
            Effect::Boxcar | Effect::Bartlett => {
                "σ(τ) below the white line for τ shorter than the filter length L·τ0 and on it \
                 beyond; the PSD has the filter's sinc² (boxcar) or sinc⁴ (Bartlett) shape"
            }
            Effect::Resonance => {
                "a bump near τ ≈ 0.37/f0 (σ ≈ 1.0·sigma for small ζ, 0.85·sigma at ζ = 0.3), \
                 falling about as 1/τ beyond it with ripples near τ = k/f0 while the oscillation \
                 lasts, then joining a −½ slope of white level N² ≈ 4ζ·sigma²/(2πf0) for τ ≫ \
                 1/(2πζf0); a peak of finite width (≈ 2ζ·f0) in the PSD, not a line"
            }
            Effect::User(u) => &u.signature,
        }
    }

    /// A paragraph on the physics: cause in a MEMS IMU, typical MPU-6050 magnitude, Allan look.
    pub fn physics(&self) -> &str {
        match self {
            Effect::Quantization => {
                "Quantization noise is white noise on the integrated output (angle or velocity): \
                 the rounding error of a quantizer that accumulates rate into counts, or timing \
                 jitter of the samples. On a rate-output MEMS part such as the MPU-6050 the rate \
                 LSB (1/131 °/s at ±250 °/s) rounds each sample, which adds white rate noise \
                 (the resolution effect); a genuine Q term usually comes from sample-time jitter \
                 or from digital filtering/decimation. Typical fitted Q on an MPU-6050 at 100 Hz \
                 is a few 1e-4 °. It dominates only the first one or two octaves of τ."
            }
            Effect::White => {
                "White rate noise (angle/velocity random walk): thermo-mechanical (Brownian) \
                 noise of the proof mass and electronic noise of the capacitive readout, flat in \
                 frequency up to the filter bandwidth. Integrating it gives an angle that random \
                 walks as N·√t. The MPU-6050 datasheet gives 0.005 °/s/√Hz (N ≈ 0.3 °/√h) for the \
                 gyro and 400 µg/√Hz for the accelerometer; measured parts are often 1–2× that. \
                 It is the −½ slope that dominates short τ."
            }
            Effect::Flicker => {
                "Flicker (1/f) noise of the bias, called bias instability: produced by charge \
                 trapping in the electronics and slow fluctuations in the MEMS structure and its \
                 package. It sets the floor of the Allan curve, the best bias estimate the sensor \
                 allows by averaging. MPU-6050 gyros show B of roughly 5–30 °/h; accelerometers \
                 some tens of µg. Flat region of the Allan plot around its minimum."
            }
            Effect::RateRandomWalk => {
                "Rate random walk: the bias itself random walks (integrated white noise on the \
                 rate), driven by temperature changes, package stress relaxation and slow \
                 electronic drift. It decides how long a bias calibration stays valid (the use \
                 Jaime et al. make of it for recalibration planning). On an MPU-6050 at room \
                 conditions K is of order 0.001–0.01 °/s/√s and needs recordings of many minutes \
                 to hours to appear. Slope +½ at long τ. A bias step or a temperature-driven drift \
                 looks the same on the Allan plot; the lab checks the time series for those."
            }
            Effect::RateRamp => {
                "Rate ramp: a deterministic, monotonic bias drift over the record — warm-up after \
                 power-on, a steady temperature change, or a slow motion of the platform. Often \
                 the first minutes of an MPU-6050 recording drift by 0.01–0.1 °/s while the die \
                 warms. It appears as slope +1 at the longest τ, and a longer warm-up before \
                 recording usually removes it. It is a non-stationarity, not a noise: its value \
                 describes this record, not the sensor."
            }
            Effect::Markov => {
                "Exponentially correlated (first-order Gauss–Markov) noise: a noise with finite \
                 memory τ_c, from a mechanical or thermal relaxation with a time constant, or a \
                 slowly fluctuating defect. It makes a bump on the Allan curve (slope +½ rising to \
                 a maximum near τ ≈ 1.9·τ_c, then −½). White noise shaped by the sensor's own \
                 low-pass filter is the lowpass effect, which ties the correlated part to the \
                 white noise it filters."
            }
            Effect::Sinusoid => {
                "A sinusoidal disturbance: vibration of the bench or a fan, mains pickup \
                 (50/60 Hz aliased by the sampling), a periodic temperature cycle of an air \
                 conditioner or heater, or a beat between the sensor's internal clock and the \
                 host's sampling. It gives an oscillating Allan curve with nulls at τ = k/f and a \
                 single line in the power spectral density."
            }
            Effect::Resolution => {
                "Resolution: each rate sample is an integer number of LSBs, so rounding adds a \
                 white error of LSB²/12 per sample. The LSB is read from the spacing of the values \
                 (the lattice they sit on); the white term N then describes the sensor's own \
                 noise above that floor. When N² approaches LSB²·τ0/12, the channel is \
                 resolution-limited and a finer range or more gain would show more of its noise."
            }
            Effect::BiasStep => {
                "A bias step: the bias jumps at one instant — a mechanical shock, a change of \
                 the sensor's range or filter setting, a brown-out and re-initialisation, or a \
                 solder joint or connector that shifts. It is not noise: averaged over the record \
                 it looks like a rate random walk of K² ≈ Δ²/T, which says nothing about the \
                 sensor's long-term stability. The step is located by a change-point test on the \
                 time series and estimated there."
            }
            Effect::Temperature => {
                "Temperature sensitivity of the bias: the MEMS structure and its readout change \
                 with die temperature (thermal stress, the drive amplitude), so the bias follows \
                 the temperature — typically 0.01–0.05 °/s/°C for an MPU-6050 gyro and ~1 mg/°C \
                 for its accelerometer. With a temperature column the coefficient is regressed on \
                 it and the Allan curve is shown before and after compensation; without one, a \
                 warm-up after power-on shows as an exponential approach of the bias with a time \
                 constant of minutes. Like a ramp it is a non-stationarity of this record."
            }
            Effect::Drift { .. } => {
                "A smooth drift of the bias over the record: thermal settling of the package and \
                 the board without a temperature column to regress on, a slow change of the \
                 supply or of the mounting stress, a turn-on transient that is not one \
                 exponential. It is a non-stationarity of this record, not a noise of the sensor: \
                 it is described as a sum of a few cosines of the record's length (periods 2T, \
                 2T/2, … — the slowest terms of a discrete cosine transform), their number chosen \
                 by the penalised criterion, tested in the time domain against the noise model \
                 and removed before the noise terms are read. A long record at a settled \
                 temperature does not show it; repeat the run to tell it from a rate random walk."
            }
            Effect::Lowpass => {
                "The sensor's own digital low-pass filter on its white noise, one pole at f_c: \
                 the MPU-6050's DLPF (DLPF_CFG 1–6: 188, 98, 42, 20, 10, 5 Hz gyro bandwidth in \
                 its register map) or an analog anti-alias filter. Sampled, it is a Gauss–Markov \
                 sequence with τ_c = 1/(2πf_c) whose variance is fixed by the white noise it \
                 filters, so it has one parameter fewer than a free Markov term."
            }
            Effect::Lowpass2 => {
                "A two-pole digital low-pass on the sensor's white noise (two cascaded \
                 first-order sections at f_c): many MEMS parts implement their DLPF as a \
                 second-order section; it falls off twice as steeply above f_c as one pole."
            }
            Effect::Boxcar => {
                "A moving-average (boxcar) decimation filter: the part samples its sensing \
                 element internally at a higher rate and outputs the mean of the last L output \
                 periods' worth of internal samples (CIC/sinc filters of sigma-delta readouts). \
                 Neighbouring output samples then share internal samples and are correlated for \
                 L samples."
            }
            Effect::Bartlett => {
                "A triangular (Bartlett, sinc²) decimation filter: two boxcar stages of L output \
                 samples in cascade, common in MEMS readouts (second-order CIC); it correlates the \
                 output for 2L samples with a smoother shape than a single boxcar."
            }
            Effect::Resonance => {
                "A resonance: white noise driving a damped harmonic oscillator, x'' + 2ζω0x' + \
                 ω0²x = w, the second-order Gauss–Markov process (Maybeck, Stochastic Models, \
                 Estimation and Control, vol. 1, ch. 4; IEEE Std 952-1997 Annex C has the \
                 correlated terms it generalises). In an IMU record it is a mechanical mode \
                 excited by broadband vibration: the board on its standoffs, the mount, a cable or \
                 the vehicle's structure, typically 5–50 Hz with ζ of 0.02–0.3. The MPU-6050's own \
                 proof-mass modes lie in the kHz range (its datasheet gives gyro mechanical \
                 frequencies of 24–36 kHz), far above any output rate, so a resonance at 1–50 Hz \
                 belongs to the mount or the structure and changes when the sensor is mounted \
                 differently. It shows as a band of excess power of width ≈ 2ζf0 in the PSD, \
                 unlike a sinusoid's line, and as a bump near τ ≈ 0.37/f0 on the Allan plot; a \
                 first-order Markov process has no oscillation and the lowpass filters no peak."
            }
            Effect::User(u) => &u.physics,
        }
    }
}
