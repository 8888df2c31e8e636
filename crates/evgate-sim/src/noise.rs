//! Noise events: shot noise (ON and OFF), leak events (ON) and optional hot pixels, as Poisson
//! processes over the whole array whose event times carry over between render steps.

use evgate_core::Event;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::esim::{LabelledEvent, PixelState};
use crate::event_model::EventModel;

/// Continuous-time noise generator.
#[derive(Clone, Debug)]
pub struct NoiseSource {
    pixels: usize,
    width: usize,
    /// Events per µs over the whole array (shot + leak).
    background_rate: f64,
    /// Share of background events that are leak (ON) events.
    leak_share: f64,
    hot_pixels: Vec<usize>,
    /// Events per µs over all hot pixels.
    hot_rate: f64,
    next_background_us: f64,
    next_hot_us: f64,
}

impl NoiseSource {
    pub fn new(
        model: &EventModel,
        width: usize,
        pixels: usize,
        rng: &mut ChaCha8Rng,
    ) -> NoiseSource {
        let per_pixel = (model.shot_noise_hz + model.leak_noise_hz) as f64;
        let background_rate = per_pixel * pixels as f64 * 1e-6;
        let leak_share = if per_pixel > 0.0 {
            model.leak_noise_hz as f64 / per_pixel
        } else {
            0.0
        };
        let hot_count = (model.hot_pixel_fraction as f64 * pixels as f64).round() as usize;
        let hot_pixels: Vec<usize> = (0..hot_count).map(|_| rng.gen_range(0..pixels)).collect();
        let hot_rate = hot_count as f64 * model.hot_pixel_hz as f64 * 1e-6;
        let mut source = NoiseSource {
            pixels,
            width,
            background_rate,
            leak_share,
            hot_pixels,
            hot_rate,
            next_background_us: f64::INFINITY,
            next_hot_us: f64::INFINITY,
        };
        source.next_background_us = exponential_gap(source.background_rate, rng);
        source.next_hot_us = exponential_gap(source.hot_rate, rng);
        source
    }

    /// Appends the noise events in `(t0_us, t1_us]`, respecting each pixel's refractory period.
    pub fn emit(
        &mut self,
        t1_us: i64,
        refractory_us: i64,
        state: &mut PixelState,
        rng: &mut ChaCha8Rng,
        out: &mut Vec<LabelledEvent>,
    ) {
        while self.next_background_us <= t1_us as f64 {
            let t = self.next_background_us.ceil() as i64;
            let pixel = rng.gen_range(0..self.pixels);
            let on = rng.gen_bool(self.leak_share) || rng.gen_bool(0.5);
            self.push(pixel, t, on, refractory_us, state, out);
            self.next_background_us += exponential_gap(self.background_rate, rng);
        }
        while self.next_hot_us <= t1_us as f64 {
            let t = self.next_hot_us.ceil() as i64;
            let pixel = self.hot_pixels[rng.gen_range(0..self.hot_pixels.len())];
            self.push(pixel, t, true, refractory_us, state, out);
            self.next_hot_us += exponential_gap(self.hot_rate, rng);
        }
    }

    fn push(
        &self,
        pixel: usize,
        t: i64,
        on: bool,
        refractory_us: i64,
        state: &mut PixelState,
        out: &mut Vec<LabelledEvent>,
    ) {
        if state.try_fire(pixel, t, refractory_us) {
            let (x, y) = ((pixel % self.width) as u16, (pixel / self.width) as u16);
            out.push(LabelledEvent {
                event: Event::new(t, x, y, on),
                label: 0,
            });
        }
    }
}

fn exponential_gap(rate_per_us: f64, rng: &mut ChaCha8Rng) -> f64 {
    if rate_per_us <= 0.0 {
        return f64::INFINITY;
    }
    let u: f64 = rng.gen_range(f64::EPSILON..1.0);
    -u.ln() / rate_per_us
}
