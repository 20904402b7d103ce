//! A small deterministic generator for the tests (no dependency on the code under test).
#![allow(dead_code)]

pub struct Lcg(pub u64);

impl Lcg {
    /// Uniform in [−1, 1).
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    pub fn arr<const N: usize>(&mut self) -> [f64; N] {
        std::array::from_fn(|_| self.next())
    }

    pub fn vec(&mut self) -> glam::DVec3 {
        glam::DVec3::from_array(self.arr())
    }
}
