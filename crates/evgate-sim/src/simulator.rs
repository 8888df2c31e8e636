//! The simulated event camera: renders the scene as often as its motion requires and turns
//! log-intensity changes into labelled events, incrementally (`advance`) so it can stream in
//! real time; also answers ground-truth queries (masks, depth, flow) at any time.
//!
//! Each region is sampled at the rate its own motion needs: the static world is rendered
//! whenever its image has moved by `max-step-px` and its log intensity is interpolated
//! linearly in between (as ESIM interpolates between any two renders), while the pixels that
//! moving objects may cover are re-evaluated at the objects' faster rate, with the objects
//! ray-cast exactly over the interpolated static world.

use std::collections::VecDeque;
use std::num::NonZeroUsize;
use std::ops::Range;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

use evgate_core::SensorSize;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::camera::{project_world, Intrinsics};
use crate::config::SimConfig;
use crate::esim::{split_off_front, split_off_front_shared, LabelledEvent, PixelBand, PixelState};
use crate::event_sort::EventSorter;
use crate::noise::NoiseSource;
use crate::photo::{load_photographs, PhotoError};
use crate::preset::Preset;
use crate::readout_delay::ReadoutDelay;
use crate::render::{Frame, RowScratch, Snapshot};
use crate::scene::Scene;
use crate::world::{build_scene, TEXTURE_SIZE};

/// Rendering probes image motion over this interval to choose the next step (of the static
/// world or of the objects).
const MOTION_PROBE_US: i64 = 1_000;
/// A step's next band takes this share of the rows left per worker (see [`band_rows`]).
const BAND_SHARE_DIVISOR: usize = 2;
/// Fewest rows in a band (but the last): smaller bands cost more to hand out than they save.
const MIN_BAND_ROWS: usize = 4;
/// Spacing of the pixel grid whose static-world points are followed by the motion probe.
const MOTION_PROBE_GRID_PX: usize = 16;

#[derive(Debug, thiserror::Error)]
pub enum SimulatorError {
    #[error(
        "simulator config: field `events.{field}` = {value} is out of range; accepted: {accepted}"
    )]
    BadEventModel {
        field: &'static str,
        value: f64,
        accepted: &'static str,
    },
    #[error(
        "simulator config: sensor size {0} has no pixels; width and height must be at least 1"
    )]
    EmptySensor(SensorSize),
    #[error("simulator config: field `scene.photographs`: {0}")]
    Photograph(#[from] PhotoError),
    #[error("simulator config: field `scene.{field}` = {value} is invalid; accepted: {accepted}")]
    BadScene {
        field: &'static str,
        value: String,
        accepted: &'static str,
    },
}

/// Counters of a run so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub struct SimStats {
    /// Instants at which the image was sampled to generate events (not counting ground-truth
    /// queries): the objects' rate where objects move, the static world's elsewhere.
    pub renders: u64,
    /// Full renders of the static world among them (its log intensity is interpolated
    /// between them).
    pub background_renders: u64,
    pub events: u64,
    pub on_events: u64,
    /// Events caused by moving objects (label > 0).
    pub object_events: u64,
    /// Simulated time covered, µs.
    pub simulated_us: i64,
}

impl SimStats {
    fn record(&mut self, delivered: &[LabelledEvent]) {
        for labelled in delivered {
            self.events += 1;
            self.on_events += labelled.event.is_on() as u64;
            self.object_events += (labelled.label != 0) as u64;
        }
    }
}

/// A deterministic (given config and seed) simulated event camera with ground truth.
pub struct Simulator {
    config: SimConfig,
    seed: u64,
    scene: Scene,
    rng: ChaCha8Rng,
    state: PixelState,
    noise: NoiseSource,
    /// The static world's log intensity at `rendered_us`.
    background: Vec<f32>,
    /// The static world's next render (its log intensity).
    next_background: Vec<f32>,
    rendered_us: i64,
    delivered_us: i64,
    /// The last step's events, unsorted, in parts (one per worker, then the noise): the next
    /// step sorts them into `pending` while its helpers render.
    unsorted: Vec<Vec<LabelledEvent>>,
    /// The step whose events are in `unsorted`, if any: the simulator renders one step
    /// ahead of the time it delivered, so that each step's sort overlaps the next step's
    /// rendering.
    unsorted_step: Option<UnsortedStep>,
    sorter: EventSorter,
    /// Emptied event buffers, kept with their capacity: allocated afresh every step, they
    /// cost page faults (large allocations come straight from the kernel).
    spare_buffers: Mutex<Vec<Vec<LabelledEvent>>>,
    /// The static world's step from `rendered_us`, sized during the step before (by its main
    /// thread, while the helpers render).
    next_static_step_us: Option<i64>,
    pending: VecDeque<LabelledEvent>,
    threads: usize,
    /// The `threads - 1` helpers that render beside the calling thread, started at the first
    /// step: a thread started per step cost each step its stack's page faults and a wake-up.
    helpers: Option<rayon::ThreadPool>,
    stats: SimStats,
    /// Timestamp jitter, when the event model asks for it.
    readout_delay: Option<ReadoutDelay>,
    /// The crossings of an `advance` call before their readout delay.
    crossings: Vec<LabelledEvent>,
}

impl Simulator {
    /// Builds the scene of `preset` for `seed`.
    pub fn from_preset(preset: Preset, seed: u64) -> Simulator {
        Simulator::new(preset.config(), seed)
            .unwrap_or_else(|e| unreachable!("preset {preset} is valid: {e}"))
    }

    /// Builds a scene from `config` and `seed` and renders it at t = 0.
    pub fn new(config: SimConfig, seed: u64) -> Result<Simulator, SimulatorError> {
        if let Some((field, value, accepted)) = config.events.invalid_field() {
            return Err(SimulatorError::BadEventModel {
                field,
                value,
                accepted,
            });
        }
        if config.sensor.pixels() == 0 {
            return Err(SimulatorError::EmptySensor(config.sensor));
        }
        let scene_params = &config.scene;
        if scene_params.min_objects > scene_params.max_objects {
            return Err(SimulatorError::BadScene {
                field: "min-objects",
                value: format!(
                    "{} (max-objects {})",
                    scene_params.min_objects, scene_params.max_objects
                ),
                accepted: "at most max-objects",
            });
        }
        if !(scene_params.object_size_m[0] > 0.0
            && scene_params.object_size_m[0] <= scene_params.object_size_m[1])
        {
            return Err(SimulatorError::BadScene {
                field: "object-size-m",
                value: format!("{:?}", scene_params.object_size_m),
                accepted: "[min, max] with 0 < min <= max",
            });
        }
        let photographs = load_photographs(&scene_params.photographs, TEXTURE_SIZE)?;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let scene = build_scene(&config, &photographs, &mut rng);
        let pixels = config.sensor.pixels();
        let mut frame = Frame::new(pixels);
        let threads = std::thread::available_parallelism()
            .map(NonZeroUsize::get)
            .unwrap_or(1);
        render_parallel(
            &Snapshot::new(&scene, 0.0),
            &mut frame,
            config.sensor,
            threads,
        );
        let state = PixelState::new(
            &config.events,
            &frame.log_intensity,
            &frame.surface,
            &mut rng,
        );
        let noise = NoiseSource::new(
            &config.events,
            config.sensor.width as usize,
            pixels,
            &mut rng,
        );
        render_parallel(
            &Snapshot::static_world(&scene, 0.0),
            &mut frame,
            config.sensor,
            threads,
        );
        let readout_delay = (config.events.timestamp_jitter_us > 0.0)
            .then(|| ReadoutDelay::new(config.events.timestamp_jitter_us, seed));
        Ok(Simulator {
            config,
            seed,
            scene,
            rng,
            state,
            noise,
            background: frame.log_intensity.clone(),
            next_background: frame.log_intensity,
            rendered_us: 0,
            delivered_us: 0,
            unsorted: Vec::new(),
            unsorted_step: None,
            sorter: EventSorter::default(),
            spare_buffers: Mutex::new(Vec::new()),
            next_static_step_us: None,
            pending: VecDeque::new(),
            threads,
            helpers: None,
            stats: SimStats::default(),
            readout_delay,
            crossings: Vec::new(),
        })
    }

    /// Limits rendering to `threads` worker threads (at least one).
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
        self.helpers = None;
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    pub fn sensor(&self) -> SensorSize {
        self.config.sensor
    }

    pub fn intrinsics(&self) -> Intrinsics {
        self.config.intrinsics
    }

    /// Number of moving objects in the scene (their ids are 1..=count).
    pub fn object_count(&self) -> usize {
        self.scene.objects.len()
    }

    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// End of the time already delivered by [`Simulator::advance`], µs.
    pub fn time_us(&self) -> i64 {
        self.delivered_us
    }

    /// Appends to `out` the events in `(time_us(), t_end_us]`, in time order. The events do not
    /// depend on how the time is split into calls.
    pub fn advance(&mut self, t_end_us: i64, out: &mut Vec<LabelledEvent>) {
        let first = out.len();
        if let Some(mut readout_delay) = self.readout_delay.take() {
            let mut crossings = std::mem::take(&mut self.crossings);
            crossings.clear();
            self.advance_crossings(t_end_us, &mut crossings);
            readout_delay.delay(&crossings, t_end_us, out);
            self.crossings = crossings;
            self.readout_delay = Some(readout_delay);
        } else {
            self.advance_crossings(t_end_us, out);
        }
        self.stats.record(&out[first..]);
    }

    /// [`Simulator::advance`] without the readout delay: events at their threshold crossings.
    fn advance_crossings(&mut self, t_end_us: i64, out: &mut Vec<LabelledEvent>) {
        // Pending events precede those of every step still to come.
        self.deliver_pending(t_end_us, out);
        // Each step sorts the step before it, so the loop ends one step past `t_end_us`: the
        // sort that a stream's every call needs then runs beside the helpers' rendering
        // instead of after it, with the helpers idle.
        while self.sorted_us() < t_end_us {
            self.step(t_end_us, out);
        }
        self.deliver_pending(t_end_us, out);
        self.delivered_us = self.delivered_us.max(t_end_us);
        self.stats.simulated_us = self.delivered_us;
    }

    /// The time up to which every event is sorted (delivered or pending).
    fn sorted_us(&self) -> i64 {
        self.unsorted_step
            .as_ref()
            .map_or(self.rendered_us, |step| step.t0_us)
    }

    /// Moves the pending events due by `t_end_us` (the queue is in time order) to `out`, in
    /// bulk.
    fn deliver_pending(&mut self, t_end_us: i64, out: &mut Vec<LabelledEvent>) {
        let due_at = |part: &[LabelledEvent]| part.partition_point(|e| e.event.t <= t_end_us);
        let (front, back) = self.pending.as_slices();
        let due_front = due_at(front);
        let due = if due_front < front.len() {
            [&front[..due_front], &[][..]]
        } else {
            [front, &back[..due_at(back)]]
        };
        for part in due {
            out.extend_from_slice(part);
        }
        let count = due[0].len() + due[1].len();
        self.pending.drain(..count);
    }

    /// One step of the static world, sized by its image motion, with the objects sampled at
    /// their own rate within it.
    /// The previous step's events are delivered meanwhile (see [`deliver`]).
    fn step(&mut self, t_end_us: i64, out: &mut Vec<LabelledEvent>) {
        let t0 = self.rendered_us;
        let step_us = self
            .next_static_step_us
            .take()
            .unwrap_or_else(|| Simulator::static_step_us(&self.scene, &self.config, t0));
        let t1 = t0 + step_us;
        let width = self.config.sensor.width as usize;
        let height = self.config.sensor.height as usize;
        let mut samples = vec![Sample::at(&self.scene, t0, t0, t1)];
        let mut t = t0;
        while t < t1 {
            t = (t + self.object_step_us(t, &samples[samples.len() - 1].snapshot)).min(t1);
            samples.push(Sample::at(&self.scene, t, t0, t1));
        }
        // Pixels outside every object's bounds at every sample see only the static world,
        // linear in time over the step: one comparison at its end gives all their events.
        let mut object_region = vec![0..0; height];
        for sample in &samples {
            sample.snapshot.extend_object_region(&mut object_region);
        }
        let interval = Interval {
            t0_us: t0,
            t1_us: t1,
            background: Snapshot::static_world(&self.scene, t1 as f32 * 1e-6),
            samples,
            object_region,
            width,
            refractory_us: self.config.events.refractory_us,
        };
        let band_rows = band_rows(height, self.threads);
        let mut parts = Vec::with_capacity(self.threads + 1);
        {
            let bands = self.state.bands(width, &band_rows);
            let (mut background, mut next_background) =
                (&self.background[..], &mut self.next_background[..]);
            let mut first_row = 0;
            let jobs = band_rows.iter().zip(bands).map(|(&rows, band)| {
                let job = BandJob {
                    first_row,
                    background: split_off_front_shared(&mut background, rows * width),
                    next_background: split_off_front(&mut next_background, rows * width),
                    band,
                };
                first_row += rows;
                job
            });
            // Workers take the next band as they finish one, so that a worker with costlier
            // rows (objects, near floors) or less CPU (a shared machine) holds the step up
            // less than with bands dealt out in advance.
            let queue: Vec<Mutex<Option<BandJob<'_>>>> =
                jobs.map(|job| Mutex::new(Some(job))).collect();
            let next_band = AtomicUsize::new(0);
            let interval = &interval;
            let (queue, next_band) = (&queue, &next_band);
            let spare_buffers = &self.spare_buffers;
            let take_buffer = move || {
                spare_buffers
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .pop()
                    .unwrap_or_default()
            };
            let run_all = move || {
                let mut out = take_buffer();
                let mut scratch = interval.background.row_scratch();
                while let Some(slot) = queue.get(next_band.fetch_add(1, Ordering::Relaxed)) {
                    let job = slot.lock().unwrap_or_else(PoisonError::into_inner).take();
                    if let Some(job) = job {
                        job.run(interval, &mut scratch, &mut out);
                    }
                }
                out
            };
            let (unsorted, sorter, pending) =
                (&mut self.unsorted, &mut self.sorter, &mut self.pending);
            let (scene, config) = (&self.scene, &self.config);
            let next_static_step_us = &mut self.next_static_step_us;
            // The previous step's sort and the next step's motion probe, which would leave the
            // helpers idle between steps, overlap their rendering of this one.
            let mut main_share = || {
                deliver(unsorted, sorter, spare_buffers, pending, t_end_us, out);
                *next_static_step_us = Some(Simulator::static_step_us(scene, config, t1));
                run_all()
            };
            let helper_count = self.threads - 1;
            if helper_count == 0 {
                parts.push(main_share());
            } else {
                let helpers = self.helpers.get_or_insert_with(|| {
                    rayon::ThreadPoolBuilder::new()
                        .num_threads(helper_count)
                        .thread_name(|i| format!("evgate-sim-{i}"))
                        .build()
                        .unwrap_or_else(|e| panic!("starting the simulator's helper threads: {e}"))
                });
                let helper_parts = Mutex::new(Vec::with_capacity(helper_count));
                helpers.in_place_scope(|scope| {
                    for _ in 0..helper_count {
                        scope.spawn(|_| {
                            let part = run_all();
                            helper_parts
                                .lock()
                                .unwrap_or_else(PoisonError::into_inner)
                                .push(part);
                        });
                    }
                    parts.push(main_share());
                });
                parts.extend(
                    helper_parts
                        .into_inner()
                        .unwrap_or_else(PoisonError::into_inner),
                );
            }
            parts.push(take_buffer());
        }
        std::mem::swap(&mut self.background, &mut self.next_background);
        let refractory = self.config.events.refractory_us;
        let noise = parts.last_mut().expect("the noise part");
        self.noise
            .emit(t1, refractory, &mut self.state, &mut self.rng, noise);
        self.unsorted = parts;
        self.rendered_us = t1;
        // A step's renders count once its events are sorted: the counters then cover the
        // time delivered, whatever was rendered ahead.
        if let Some(sorted) = self.unsorted_step.replace(UnsortedStep {
            t0_us: t0,
            renders: interval.samples.len() as u64 - 1,
        }) {
            self.stats.renders += sorted.renders;
            self.stats.background_renders += 1;
        }
    }

    /// Largest image displacement of the points in `now` after [`MOTION_PROBE_US`] in
    /// `later`, as a step that keeps it within `max-step-px`.
    fn step_for_shift(config: &SimConfig, max_shift: f32) -> i64 {
        let model = &config.events;
        let speed_px_per_us = max_shift / MOTION_PROBE_US as f32;
        let step = if speed_px_per_us > 0.0 {
            (model.max_step_px / speed_px_per_us) as i64
        } else {
            model.max_step_us
        };
        step.clamp(model.min_step_us, model.max_step_us)
    }

    /// The step from `t_us` that keeps the largest image displacement of the static world (a
    /// grid of sample pixels) within `max-step-px`.
    fn static_step_us(scene: &Scene, config: &SimConfig, t_us: i64) -> i64 {
        let now = Snapshot::static_world(scene, t_us as f32 * 1e-6);
        let later = Snapshot::static_world(scene, (t_us + MOTION_PROBE_US) as f32 * 1e-6);
        let k = &config.intrinsics;
        let sensor = config.sensor;
        let mut max_shift = 0.0f32;
        for y in (MOTION_PROBE_GRID_PX / 2..sensor.height as usize).step_by(MOTION_PROBE_GRID_PX) {
            for x in (MOTION_PROBE_GRID_PX / 2..sensor.width as usize).step_by(MOTION_PROBE_GRID_PX)
            {
                if let Some(point) = now.static_point(x as f32, y as f32) {
                    if let Some(b) = project_world(k, later.camera(), point) {
                        max_shift = max_shift.max(shift((x as f32, y as f32), b));
                    }
                }
            }
        }
        Simulator::step_for_shift(config, max_shift)
    }

    /// The step from `t_us` (whose snapshot is `now`) that keeps the largest image
    /// displacement of every object's bounding-box corners near the view within
    /// `max-step-px`.
    fn object_step_us(&self, t_us: i64, now: &Snapshot<'_>) -> i64 {
        let later = Snapshot::new(&self.scene, (t_us + MOTION_PROBE_US) as f32 * 1e-6);
        let k = &self.config.intrinsics;
        let sensor = self.config.sensor;
        let on_screen = |p: Option<(f32, f32)>| {
            p.is_some_and(|(x, y)| {
                x > -50.0
                    && y > -50.0
                    && x < sensor.width as f32 + 50.0
                    && y < sensor.height as f32 + 50.0
            })
        };
        let mut max_shift = 0.0f32;
        for (i, object) in self.scene.objects.iter().enumerate() {
            let id = i as u16 + 1;
            for corner in object.shape.corners() {
                let before = project_world(k, now.camera(), now.object_pose(id).to_world(corner));
                let after =
                    project_world(k, later.camera(), later.object_pose(id).to_world(corner));
                if let (true, Some(a), Some(b)) =
                    (on_screen(before) || on_screen(after), before, after)
                {
                    max_shift = max_shift.max(shift(a, b));
                }
            }
        }
        Simulator::step_for_shift(&self.config, max_shift)
    }

    /// Renders the scene at `t_us` (log intensity, surface id, depth) without touching the
    /// event state.
    pub fn frame_at(&self, t_us: i64) -> Frame {
        let mut frame = Frame::new(self.config.sensor.pixels());
        render_parallel(
            &Snapshot::new(&self.scene, t_us as f32 * 1e-6),
            &mut frame,
            self.config.sensor,
            self.threads,
        );
        frame
    }

    /// The surface ids and depths of [`Simulator::frame_at`] (bit for bit), without its
    /// shading, which ground truth does not need.
    pub fn surfaces_at(&self, t_us: i64) -> Surfaces {
        let sensor = self.config.sensor;
        let mut surfaces = Surfaces {
            id: vec![0; sensor.pixels()],
            depth: vec![0.0; sensor.pixels()],
        };
        let snapshot = Snapshot::new(&self.scene, t_us as f32 * 1e-6);
        let width = sensor.width as usize;
        let chunk = width * (sensor.height as usize).div_ceil(self.threads.max(1));
        std::thread::scope(|scope| {
            for (i, (id, depth)) in surfaces
                .id
                .chunks_mut(chunk)
                .zip(surfaces.depth.chunks_mut(chunk))
                .enumerate()
            {
                let snapshot = &snapshot;
                scope.spawn(move || {
                    snapshot.locate_rows(i * chunk / width, id, depth, &mut snapshot.row_scratch())
                });
            }
        });
        surfaces
    }

    /// Object id per pixel at `t_us` (0 = static world).
    pub fn mask_at(&self, t_us: i64) -> Vec<u16> {
        self.surfaces_at(t_us).id
    }

    /// Depth in metres per pixel at `t_us` (`f32::INFINITY` where no surface is hit).
    pub fn depth_at(&self, t_us: i64) -> Vec<f32> {
        self.surfaces_at(t_us).depth
    }

    /// Forward optical flow (dx, dy) in pixels from `t_us` to `t_us + horizon_us`, defined at
    /// each pixel at `t_us`: where the surface point seen there projects at the later time
    /// (whether or not it is visible then). NaN where the point is behind the camera then.
    pub fn flow(&self, t_us: i64, horizon_us: i64) -> Vec<[f32; 2]> {
        let sensor = self.config.sensor;
        let width = sensor.width as usize;
        let now = Snapshot::new(&self.scene, t_us as f32 * 1e-6);
        let later = Snapshot::new(&self.scene, (t_us + horizon_us) as f32 * 1e-6);
        let k = &self.config.intrinsics;
        let mut flow = vec![[0.0f32; 2]; sensor.pixels()];
        let rows_per_band = (sensor.height as usize).div_ceil(self.threads);
        std::thread::scope(|scope| {
            for (band, rows) in flow.chunks_mut(width * rows_per_band).enumerate() {
                let (now, later) = (&now, &later);
                scope.spawn(move || {
                    for (i, value) in rows.iter_mut().enumerate() {
                        let (x, y) = (
                            (i % width) as f32,
                            (band * rows_per_band + i / width) as f32,
                        );
                        let hit = now.locate(x, y);
                        let world = if hit.surface == 0 {
                            hit.point
                        } else {
                            later.object_pose(hit.surface).to_world(hit.point)
                        };
                        *value = match (
                            hit.depth.is_finite(),
                            project_world(k, later.camera(), world),
                        ) {
                            (true, Some((x1, y1))) => [x1 - x, y1 - y],
                            (false, _) => [0.0, 0.0],
                            (true, None) => [f32::NAN, f32::NAN],
                        };
                    }
                });
            }
        });
        flow
    }
}

/// What each pixel sees at one instant, without its intensity.
#[derive(Clone, Debug, PartialEq)]
pub struct Surfaces {
    /// 0 = static world, k = moving object k.
    pub id: Vec<u16>,
    /// Metres along the ray (`f32::INFINITY` where no surface is hit).
    pub depth: Vec<f32>,
}

/// Sorts a step's events (`parts`, which follow those in `pending`) and moves them on: those
/// due by `t_end_us` straight to `out` where nothing is pending (rather than through the
/// queue), the others to `pending`; the emptied parts go to `spare_buffers`. Time, then row and
/// column: the order does not depend on how rows were shared out (a stable sort keeps one
/// pixel's events in the order it produced them, and a pixel's noise after them).
fn deliver(
    parts: &mut Vec<Vec<LabelledEvent>>,
    sorter: &mut EventSorter,
    spare_buffers: &Mutex<Vec<Vec<LabelledEvent>>>,
    pending: &mut VecDeque<LabelledEvent>,
    t_end_us: i64,
    out: &mut Vec<LabelledEvent>,
) {
    let events = sorter.sort_parts(parts);
    let due = if pending.is_empty() {
        events.partition_point(|labelled| labelled.event.t <= t_end_us)
    } else {
        0
    };
    out.extend_from_slice(&events[..due]);
    pending.extend(events[due..].iter().copied());
    let mut spare = spare_buffers.lock().unwrap_or_else(PoisonError::into_inner);
    for mut part in parts.drain(..) {
        part.clear();
        spare.push(part);
    }
}

fn shift(a: (f32, f32), b: (f32, f32)) -> f32 {
    ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt()
}

/// A step rendered and not yet sorted.
struct UnsortedStep {
    t0_us: i64,
    /// Instants sampled for events in the step.
    renders: u64,
}

/// An instant at which the objects are sampled within a step of the static world.
struct Sample<'a> {
    t_us: i64,
    /// Where `t_us` lies between the static world's renders (0 at the first, 1 at the second).
    fraction: f32,
    snapshot: Snapshot<'a>,
}

impl<'a> Sample<'a> {
    fn at(scene: &'a Scene, t_us: i64, t0_us: i64, t1_us: i64) -> Sample<'a> {
        Sample {
            t_us,
            fraction: (t_us - t0_us) as f32 / (t1_us - t0_us) as f32,
            snapshot: Snapshot::new(scene, t_us as f32 * 1e-6),
        }
    }
}

/// One step of the static world from `t0_us` to `t1_us` and the object samples within it.
struct Interval<'a> {
    t0_us: i64,
    t1_us: i64,
    /// The static world at `t1_us`.
    background: Snapshot<'a>,
    /// From `t0_us` to `t1_us`.
    samples: Vec<Sample<'a>>,
    /// Per row, the columns that some object may cover at some sample.
    object_region: Vec<Range<usize>>,
    width: usize,
    refractory_us: i64,
}

/// One worker's share of a step: a band of rows, rendered then compared with its state.
struct BandJob<'a> {
    first_row: usize,
    /// The static world at the step's start, and its render at the end (written here).
    background: &'a [f32],
    next_background: &'a mut [f32],
    band: PixelBand<'a>,
}

impl BandJob<'_> {
    fn run(
        mut self,
        interval: &Interval<'_>,
        scratch: &mut RowScratch,
        out: &mut Vec<LabelledEvent>,
    ) {
        interval
            .background
            .shade_rows(self.first_row, self.next_background, scratch);
        let width = interval.width;
        let rows = self.background.len() / width;
        let refractory = interval.refractory_us;
        let mut log_intensity = vec![0.0f32; width];
        let mut surface = vec![0u16; width];
        for pair in interval.samples.windows(2) {
            let (before, sample) = (&pair[0], &pair[1]);
            let (keep, take) = (1.0 - sample.fraction, sample.fraction);
            for row in 0..rows {
                let columns = interval.object_region[self.first_row + row].clone();
                if columns.is_empty() {
                    continue;
                }
                let offset = row * width;
                for c in columns.clone() {
                    // Exactly the next render at the last sample (take = 1, keep = 0).
                    log_intensity[c] = self.background[offset + c] * keep
                        + self.next_background[offset + c] * take;
                    surface[c] = 0;
                }
                sample.snapshot.overlay_objects(
                    self.first_row + row,
                    columns.clone(),
                    &mut log_intensity[columns.clone()],
                    &mut surface[columns.clone()],
                    scratch,
                );
                for c in columns {
                    self.band.emit_pixel(
                        offset + c,
                        log_intensity[c],
                        surface[c],
                        before.t_us,
                        sample.t_us,
                        refractory,
                        out,
                    );
                }
            }
        }
        for row in 0..rows {
            let columns = &interval.object_region[self.first_row + row];
            let offset = row * width;
            for static_columns in [0..columns.start, columns.end..width] {
                let pixels = offset + static_columns.start..offset + static_columns.end;
                self.band.emit_static_run(
                    pixels.clone(),
                    &self.next_background[pixels],
                    interval.t0_us,
                    interval.t1_us,
                    refractory,
                    out,
                );
            }
        }
    }
}

/// Rows per band of a step, largest first: workers take bands as they finish one, and a
/// worker that finds no band left waits for the others' last bands, which are therefore
/// small (guided self-scheduling).
fn band_rows(height: usize, threads: usize) -> Vec<usize> {
    let mut rows = Vec::new();
    let mut left = height;
    while left > 0 {
        let band = (left / (BAND_SHARE_DIVISOR * threads))
            .max(MIN_BAND_ROWS)
            .min(left);
        rows.push(band);
        left -= band;
    }
    rows
}

fn render_parallel(snapshot: &Snapshot<'_>, frame: &mut Frame, sensor: SensorSize, threads: usize) {
    let width = sensor.width as usize;
    let rows_per_band = (sensor.height as usize).div_ceil(threads.max(1));
    let chunk = width * rows_per_band;
    std::thread::scope(|scope| {
        for (i, ((log, surface), depth)) in frame
            .log_intensity
            .chunks_mut(chunk)
            .zip(frame.surface.chunks_mut(chunk))
            .zip(frame.depth.chunks_mut(chunk))
            .enumerate()
        {
            scope.spawn(move || snapshot.render_rows(i * rows_per_band, log, surface, depth));
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_cover_every_row_once_and_shrink_towards_the_end() {
        for height in [1, 3, 4, 7, 60, 260, 480, 1000] {
            for threads in [1, 2, 3, 16] {
                let rows = band_rows(height, threads);
                assert_eq!(
                    rows.iter().sum::<usize>(),
                    height,
                    "{height} rows, {threads}"
                );
                assert!(rows.iter().all(|&r| r > 0));
                assert!(
                    rows.windows(2).all(|pair| pair[0] >= pair[1]),
                    "{height} rows, {threads} threads: {rows:?}"
                );
                let last = *rows.last().expect("a band");
                assert!(last <= MIN_BAND_ROWS.max(height / (BAND_SHARE_DIVISOR * threads)));
            }
        }
        assert!(band_rows(260, 2).len() >= 2 * 2 * BAND_SHARE_DIVISOR);
    }
}
