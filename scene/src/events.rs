//! The event stream: struct of arrays, sorted by time.
//!
//! **Timestamps are `f64` seconds** on the clock of the scene manifest (`timestamp`).
//! f64 keeps the nanosecond digits of ECD text files exactly enough (spacing below
//! 15 ns up to 10⁵ s) and needs no unit conversion in the math. Pixel coordinates are
//! integer sensor pixels (`u16`, distorted grid for real sensors; see
//! [`crate::camera::Intrinsics::undistort_pixel`]). Polarity is `+1` (brighter) or `−1`.

use std::ops::Range;

/// An owned, time-sorted event stream of a `width × height` sensor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EventStream {
    pub width: u32,
    pub height: u32,
    pub t: Vec<f64>,
    pub x: Vec<u16>,
    pub y: Vec<u16>,
    pub p: Vec<i8>,
}

/// A borrowed window of an event stream (same layout as [`EventStream`]).
#[derive(Clone, Copy, Debug)]
pub struct EventSlice<'a> {
    pub width: u32,
    pub height: u32,
    pub t: &'a [f64],
    pub x: &'a [u16],
    pub y: &'a [u16],
    pub p: &'a [i8],
    /// Index of this slice's first event in the stream it was cut from.
    pub offset: usize,
}

impl EventStream {
    pub fn new(width: u32, height: u32) -> Self {
        EventStream {
            width,
            height,
            ..Default::default()
        }
    }

    pub fn with_capacity(width: u32, height: u32, n: usize) -> Self {
        EventStream {
            width,
            height,
            t: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
        }
    }

    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    pub fn push(&mut self, t: f64, x: u16, y: u16, p: i8) {
        self.t.push(t);
        self.x.push(x);
        self.y.push(y);
        self.p.push(p);
    }

    pub fn as_slice(&self) -> EventSlice<'_> {
        EventSlice {
            width: self.width,
            height: self.height,
            t: &self.t,
            x: &self.x,
            y: &self.y,
            p: &self.p,
            offset: 0,
        }
    }

    /// Indices of the events with `t0 ≤ t < t1` (binary search: O(log n)).
    pub fn window_range(&self, t0: f64, t1: f64) -> Range<usize> {
        self.as_slice().window_range(t0, t1)
    }

    /// The events with `t0 ≤ t < t1`.
    pub fn window(&self, t0: f64, t1: f64) -> EventSlice<'_> {
        self.as_slice().window(t0, t1)
    }

    /// Sort by time (stable, so equal timestamps keep their order). Readers of formats
    /// that promise sorted input reject unsorted files instead of calling this.
    pub fn sort_by_time(&mut self) {
        if self.t.windows(2).all(|w| w[0] <= w[1]) {
            return;
        }
        let mut idx: Vec<u32> = (0..self.len() as u32).collect();
        idx.sort_by(|&a, &b| self.t[a as usize].total_cmp(&self.t[b as usize]));
        self.t = idx.iter().map(|&i| self.t[i as usize]).collect();
        self.x = idx.iter().map(|&i| self.x[i as usize]).collect();
        self.y = idx.iter().map(|&i| self.y[i as usize]).collect();
        self.p = idx.iter().map(|&i| self.p[i as usize]).collect();
    }

    /// Check the invariants every reader guarantees: equal column lengths, finite sorted
    /// timestamps, coordinates inside the sensor, polarity ±1. `Err` says which event.
    pub fn validate(&self) -> Result<(), String> {
        let n = self.t.len();
        if self.x.len() != n || self.y.len() != n || self.p.len() != n {
            return Err(format!(
                "column lengths differ: t {}, x {}, y {}, p {}",
                n,
                self.x.len(),
                self.y.len(),
                self.p.len()
            ));
        }
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "sensor size {}x{} is empty",
                self.width, self.height
            ));
        }
        for i in 0..n {
            let t = self.t[i];
            if !t.is_finite() {
                return Err(format!("event {i}: timestamp {t} is not finite"));
            }
            if i > 0 && t < self.t[i - 1] {
                return Err(format!(
                    "event {i}: timestamps not sorted ({} after {})",
                    t,
                    self.t[i - 1]
                ));
            }
            if self.x[i] as u32 >= self.width || self.y[i] as u32 >= self.height {
                return Err(format!(
                    "event {i}: pixel ({}, {}) outside the {}x{} sensor",
                    self.x[i], self.y[i], self.width, self.height
                ));
            }
            if self.p[i] != 1 && self.p[i] != -1 {
                return Err(format!("event {i}: polarity {} is not ±1", self.p[i]));
            }
        }
        Ok(())
    }
}

impl<'a> EventSlice<'a> {
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Indices (relative to this slice) of the events with `t0 ≤ t < t1` (half-open;
    /// empty when `t1 ≤ t0` or a bound is NaN).
    pub fn window_range(&self, t0: f64, t1: f64) -> Range<usize> {
        if t0.is_nan() {
            return self.t.len()..self.t.len(); // no t satisfies NaN ≤ t
        }
        let a = self.t.partition_point(|&t| t < t0);
        let b = a + self.t[a..].partition_point(|&t| t < t1);
        a..b
    }

    pub fn window(&self, t0: f64, t1: f64) -> EventSlice<'a> {
        self.sub(self.window_range(t0, t1))
    }

    /// The events at `range` (relative to this slice).
    pub fn sub(&self, range: Range<usize>) -> EventSlice<'a> {
        EventSlice {
            width: self.width,
            height: self.height,
            t: &self.t[range.clone()],
            x: &self.x[range.clone()],
            y: &self.y[range.clone()],
            p: &self.p[range.clone()],
            offset: self.offset + range.start,
        }
    }

    pub fn to_owned(&self) -> EventStream {
        EventStream {
            width: self.width,
            height: self.height,
            t: self.t.to_vec(),
            x: self.x.to_vec(),
            y: self.y.to_vec(),
            p: self.p.to_vec(),
        }
    }
}
