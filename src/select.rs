//! Selects without branches, for conditions the CPU cannot predict (a
//! coin flip of a sampling routine, the sign of a random direction's
//! component, which end of a BDPT connection is being evaluated). A
//! mispredicted branch costs ~15 cycles; a select a few instructions. LLVM
//! turns a plain `if`, and even `std::hint::select_unpredictable`, on such
//! values back into a branch on x86-64, so these go through SSE lanes and
//! integer masks, which it keeps.

use glam::{BVec4A, Vec4};

/// `if c { a } else { b }` as a lane select.
#[inline(always)]
pub fn select_f32(c: bool, a: f32, b: f32) -> f32 {
    Vec4::select(BVec4A::splat(c), Vec4::splat(a), Vec4::splat(b)).x
}

/// `if c { a } else { b }` by an all-ones or all-zeros mask.
#[inline(always)]
pub fn select_u32(c: bool, a: u32, b: u32) -> u32 {
    let m = 0u32.wrapping_sub(c as u32);
    (a & m) | (b & !m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both forms hand back the chosen value bit for bit (signed zeros,
    /// NaN payloads, subnormals), as the branches they replace did.
    #[test]
    fn selects_return_the_chosen_bits() {
        let values = [0.0f32, -0.0, 1.0, -3.5, f32::from_bits(1), f32::INFINITY, f32::from_bits(0x7fc0_1234)];
        for &a in &values {
            for &b in &values {
                assert_eq!(select_f32(true, a, b).to_bits(), a.to_bits());
                assert_eq!(select_f32(false, a, b).to_bits(), b.to_bits());
                let (ua, ub) = (a.to_bits(), b.to_bits());
                assert_eq!(select_u32(true, ua, ub), ua);
                assert_eq!(select_u32(false, ua, ub), ub);
            }
        }
    }
}
