//! The firmware's hottest path in hand-scheduled Thumb code: two steady-state samples of a
//! [`DeviceEngine`] (Thumb-1: ARMv6-M and later M-profile cores; built with the `thumb-asm`
//! feature on `target_arch = "arm"`).
//!
//! [`Engine::push_pair`] hands it every pair; it goes on only when both samples would take
//! `push_steady::<true>` (the base ring full and narrow, |z| below the gate, the gate below
//! 2^11) and the segment's sample count is even, and otherwise returns 0 having changed nothing
//! (the Rust path takes the pair then). It does exactly what two calls of `push_steady::<true>`
//! do, in the same 32-bit arithmetic, so the sums are bit for bit the same (the emulator's
//! end-to-end test compares the device's tables with the host's Rust engine). A second routine
//! does the same for one sample of either parity (`push_small`, from [`Engine::push`]), and a
//! second instance of it serves the magnetometer's [`MagEngine`] (`push_mag`): the same steps
//! with every square range-tested (one multiply when |D| < 2^15, else a 64-bit square out of
//! line), so it takes every steady sample whatever the gate (the QMC5883L's counts at the
//! bench's noise reach |y − c| ≈ 2^13, its i16 extremes 2^16 − 1); only `theta`'s offset and S
//! differ in `MagEngine`'s layout.
//!
//! The pair, step by step:
//!
//! 1. θ[t] enters base slot h = t mod 24 and its mirror h + 24; θ[t+1] and θ[t+2] are formed;
//!    `theta`, `t` and `base_head` are stored once.
//! 2. Sample 1 (count t+1): the four unit-stride levels over the window at h + 1; then θ[t+1]
//!    enters slot h + 1 (after the window was read: its oldest value lived there).
//! 3. Sample 2 (count t+2): the four unit-stride levels over the window at h + 2.
//! 4. What `cascade(t − 24, θ[t−24])` does for sample 1 (its count before the push was even):
//!    every level's ring here; then what `strided(lo θ[t+2−16])` does for sample 2 (odd): level
//!    K0 when it is full, narrow and small (its differences below 2^16) and the levels above
//!    while they are full and narrow, here; `strided` or `strided_general` for the rest. Same
//!    order as `push_steady`.
//!
//! Why by hand: LLVM spills `self`, the window pointer and θ on every level (8 low registers);
//! here each level is 2 loads, 9 ALU operations, 2 multiplies and two 32-bit sum updates with
//! the carry out of line, and the per-sample bookkeeping is shared by the pair. The cycles are
//! in docs/allan.md ("Cost on the Cortex-M0+").
//!
//! Registers in the level loop: r0 = self (the unit-stride sums are its first 128 bytes),
//! r2 = window (w[24 − a] = lo θ[t − a]), r5 = lo θ of the sample, r4/r6 = lo θ[t − m] and
//! lo θ[t − 2m] (they swap roles from level to level), r1, r3, r7 scratch.

use super::{DeviceEngine, Engine, MagEngine};
use core::mem::offset_of;

// What the code below assumes about the layout (offsets are immediates in the instructions).
const THETA: usize = offset_of!(DeviceEngine, theta);
const BASE: usize = offset_of!(DeviceEngine, base);
const T: usize = offset_of!(DeviceEngine, t);
const HEAD: usize = offset_of!(DeviceEngine, base_head);
const HEADS: usize = offset_of!(DeviceEngine, heads);
const FULL: usize = offset_of!(DeviceEngine, full);
const NARROW: usize = offset_of!(DeviceEngine, narrow);
const GATE: usize = offset_of!(DeviceEngine, gate);
const RINGS: usize = offset_of!(DeviceEngine, rings);
const OFFSET: usize = offset_of!(DeviceEngine, offset);
const _: () = {
    assert!(offset_of!(DeviceEngine, sums) == 0);
    assert!(THETA.is_multiple_of(4) && THETA / 4 <= 255);
    assert!(THETA - BASE <= 255 && BASE + 2 * 24 * 4 == THETA);
    assert!(T == THETA + 8);
    assert!(HEAD - THETA <= 31 && HEADS - THETA <= 31);
    assert!(FULL - THETA <= 31 && NARROW - THETA <= 31 && GATE - THETA <= 124);
    assert!(RINGS - THETA <= 255 && OFFSET - THETA <= 124);
};
// `MagEngine` (fewer levels: S = 18) has the same layout from `theta` on, so only `theta`'s
// offset and S differ in its routine.
const MAG_THETA: usize = offset_of!(MagEngine, theta);
const _: () = {
    assert!(offset_of!(MagEngine, sums) == 0);
    assert!(MAG_THETA.is_multiple_of(4) && MAG_THETA / 4 <= 255);
    assert!(offset_of!(MagEngine, base) == BASE - (THETA - MAG_THETA));
    assert!(offset_of!(MagEngine, t) - MAG_THETA == T - THETA);
    assert!(offset_of!(MagEngine, base_head) - MAG_THETA == HEAD - THETA);
    assert!(offset_of!(MagEngine, heads) - MAG_THETA == HEADS - THETA);
    assert!(offset_of!(MagEngine, full) - MAG_THETA == FULL - THETA);
    assert!(offset_of!(MagEngine, narrow) - MAG_THETA == NARROW - THETA);
    assert!(offset_of!(MagEngine, gate) - MAG_THETA == GATE - THETA);
    assert!(offset_of!(MagEngine, rings) - MAG_THETA == RINGS - THETA);
    assert!(offset_of!(MagEngine, offset) - MAG_THETA == OFFSET - THETA);
    assert!(super::MAG_PARAMS[3] == 18 && super::DEVICE_PARAMS[3] == 20);
};

extern "C" {
    /// One steady-state sample z (already offset, |z| < gate < 2^11), either parity.
    fn pico_imu_allan_push_small(engine: *mut DeviceEngine, z: i32);
    /// Two samples y0, y1 if they are steady-state ones (|y − offset| < gate < 2^11, t even):
    /// returns 1; else 0 and nothing changed.
    fn pico_imu_allan_push_pair_small(engine: *mut DeviceEngine, y0: i32, y1: i32) -> u32;
    /// One steady-state sample z of a `MagEngine` (already offset, |z| < gate, any gate),
    /// either parity.
    fn pico_imu_allan_mag_push(engine: *mut MagEngine, z: i32);
}

/// `push_steady::<true>` on `e` (conditions checked by the caller).
///
/// # Safety
/// The base ring is full and narrow (`gate != 0`), `gate < 2^11`, and |z| < `gate`.
#[inline(always)]
pub(super) unsafe fn push_small(e: &mut DeviceEngine, z: i32) {
    // SAFETY: the caller has checked the steady-state conditions the routine relies on; it
    // touches only `*e` (and the stack) and calls `strided`/`strided_tail` on it like
    // `push_steady` does.
    unsafe { pico_imu_allan_push_small(e, z) }
}

/// `push_steady` on a magnetometer engine `e` (conditions checked by the caller), with
/// range-tested squares: for any gate, the QMC5883L's whole i16 range included.
///
/// # Safety
/// The base ring is full and narrow (`gate != 0`) and |z| < `gate`.
#[inline(always)]
pub(super) unsafe fn push_mag(e: &mut MagEngine, z: i32) {
    // SAFETY: as for `push_small`, without the gate's upper bound (every square is
    // range-tested).
    unsafe { pico_imu_allan_mag_push(e, z) }
}

/// Two `push_steady::<true>` calls on `e` when both samples are steady-state ones and the
/// segment's count is even (the routine checks); `false`, and nothing changed, otherwise.
#[inline(always)]
pub(super) fn push_pair_small(e: &mut DeviceEngine, y0: i32, y1: i32) -> bool {
    // SAFETY: the routine checks the steady-state conditions itself before touching `*e`; it
    // touches only `*e` (and the stack) and calls `strided`/`strided_tail` on it like
    // `push_steady` does.
    unsafe { pico_imu_allan_push_pair_small(e, y0, y1) != 0 }
}

core::arch::global_asm!(
    ".pushsection .text.pico_imu_allan_push_pair_small,\"ax\",%progbits",
    // Second and third differences from r5 = lo θ[t], \tm = lo θ[t − m], \t2 = lo θ[t − 2m] and
    // \t3 = lo θ[t − 3m]: r1 = D2 = θ[t] − 2θ[t−m] + θ[t−2m], r3 = D3 = D2 − (θ[t−m] −
    // 2θ[t−2m] + θ[t−3m]), in wrapping 32-bit words (exact: both are known to fit i32).
    ".macro APP_D23 tm, t2, t3",
    "    lsls r1, \\tm, #1",
    "    subs r1, r5, r1",
    "    adds r1, r1, \\t2",
    "    lsls r3, \\t2, #1",
    "    subs r3, \\tm, r3",
    "    adds r3, r3, \\t3",
    "    subs r3, r1, r3",
    ".endm",
    // A strided level's ring (r3 = &rings[j], r2 = its head h): r7 = lo θ[t − 2m], 3 entries
    // behind the newest, r2 = lo θ[t − 3m], the oldest (the one after the newest).
    ".macro APP_RING",
    "    subs r7, r2, #3",
    "    bhs 1f",
    "    adds r7, #12",
    "1:",
    "    lsls r7, r7, #3",
    "    ldr r7, [r3, r7]",
    "    adds r2, r2, #1",
    "    cmp r2, #12",
    "    bne 2f",
    "    movs r2, #0",
    "2:",
    "    lsls r2, r2, #3",
    "    ldr r2, [r3, r2]",
    ".endm",
    // One unit-stride level: \tm = lo θ[t − m] in, \t2 = lo θ[t − 2m] out. A carry out of a
    // sum's low word (rare) branches to the level's stub after the unit block (\c numbers the
    // labels), so the common path takes no branch.
    ".macro APP_LEVEL tm, t2, o2, o3, s2, s3, c",
    "    ldr \\t2, [r2, #\\o2]",
    "    ldr r7, [r2, #\\o3]",
    "    APP_D23 \\tm, \\t2, r7",
    "    muls r1, r1, r1",
    "    muls r3, r3, r3",
    "    ldr r7, [r0, #\\s2]",
    "    adds r7, r7, r1",
    "    str r7, [r0, #\\s2]",
    "    bcs 4\\c\\()0f",
    "4\\c\\()1:",
    "    ldr r7, [r0, #\\s3]",
    "    adds r7, r7, r3",
    "    str r7, [r0, #\\s3]",
    "    bcs 4\\c\\()2f",
    "4\\c\\()3:",
    ".endm",
    // The carry stubs of level \c: word 1 and up of the sum, then back.
    ".macro APP_CARRY c, s2, s3",
    "4\\c\\()0:",
    "    movs r7, #(\\s2 + 4)",
    "    adds r7, r7, r0",
    "    bl pico_imu_allan_carry",
    "    b 4\\c\\()1b",
    "4\\c\\()2:",
    "    movs r7, #(\\s3 + 4)",
    "    adds r7, r7, r0",
    "    bl pico_imu_allan_carry",
    "    b 4\\c\\()3b",
    ".endm",
    // APP_LEVEL for any narrow input (`MagEngine`): each square with the range test of the
    // strided levels (one multiply when |D| < 2^15), a wider one out of line to the level's
    // stubs 4c5 (D2) and 4c6 (D3), which call `add_square_wide`.
    ".macro APP_LEVEL_R tm, t2, o2, o3, s2, s3, c",
    "    ldr \\t2, [r2, #\\o2]",
    "    ldr r7, [r2, #\\o3]",
    "    APP_D23 \\tm, \\t2, r7",
    "    asrs r7, r1, #15",
    "    adds r7, r7, #1",
    "    cmp r7, #1",
    "    bhi 4\\c\\()5f",
    "    muls r1, r1, r1",
    "    ldr r7, [r0, #\\s2]",
    "    adds r7, r7, r1",
    "    str r7, [r0, #\\s2]",
    "    bcs 4\\c\\()0f",
    "4\\c\\()1:",
    "    asrs r7, r3, #15",
    "    adds r7, r7, #1",
    "    cmp r7, #1",
    "    bhi 4\\c\\()6f",
    "    muls r3, r3, r3",
    "    ldr r7, [r0, #\\s3]",
    "    adds r7, r7, r3",
    "    str r7, [r0, #\\s3]",
    "    bcs 4\\c\\()2f",
    "4\\c\\()3:",
    ".endm",
    // APP_CARRY and the wide-square stubs of APP_LEVEL_R's level \c.
    ".macro APP_CARRY_R c, s2, s3",
    "    APP_CARRY \\c, \\s2, \\s3",
    "4\\c\\()5:",
    "    movs r7, #\\s2",
    "    adds r7, r7, r0",
    "    bl pico_imu_allan_add_square_wide",
    "    b 4\\c\\()1b",
    "4\\c\\()6:",
    "    mov r1, r3",
    "    movs r7, #\\s3",
    "    adds r7, r7, r0",
    "    bl pico_imu_allan_add_square_wide",
    "    b 4\\c\\()3b",
    ".endm",
    // The four unit-stride levels of one sample (P = 8): leaves lo θ[t − 16] in r4. \mag = 1:
    // with range-tested squares (any narrow input), else with one multiply (gate < 2^11).
    ".macro APP_UNIT mag",
    "    ldr r4, [r2, #92]",
    ".if \\mag",
    "    APP_LEVEL_R r4, r6, 88, 84, 0, 16, 1",
    "    APP_LEVEL_R r6, r4, 80, 72, 32, 48, 2",
    "    APP_LEVEL_R r4, r6, 64, 48, 64, 80, 3",
    "    APP_LEVEL_R r6, r4, 32, 0, 96, 112, 4",
    "    b 499f",
    "    APP_CARRY_R 1, 0, 16",
    "    APP_CARRY_R 2, 32, 48",
    "    APP_CARRY_R 3, 64, 80",
    "    APP_CARRY_R 4, 96, 112",
    ".else",
    "    APP_LEVEL r4, r6, 88, 84, 0, 16, 1",
    "    APP_LEVEL r6, r4, 80, 72, 32, 48, 2",
    "    APP_LEVEL r4, r6, 64, 48, 64, 80, 3",
    "    APP_LEVEL r6, r4, 32, 0, 96, 112, 4",
    "    b 499f",
    "    APP_CARRY 1, 0, 16",
    "    APP_CARRY 2, 32, 48",
    "    APP_CARRY 3, 64, 80",
    "    APP_CARRY 4, 96, 112",
    ".endif",
    "499:",
    ".endm",
    // The cascade for a sample whose count t_c (before it) was even, as `cascade` does.
    // In: r0 = self, r5 = lo θ now, [sp] = lo θ[t_c − 24], [sp, #4] = t_c. Out: r6 = &theta,
    // [sp, #8] = self; r4 and r5 kept.
    ".macro APP_CASCADE theta4, s",
    // Sample 1's cascade (its count t was even), as `cascade` does: θ[t − 24] enters level
    // K0's ring; the value it displaces moves on (`cascade_up`) if its index is a multiple of 4.
    // θ[t − 24] = θ[t+2] − (lo θ[t+2] − lo θ[t−24]) as i32, exact (26 samples below 2^11).
    "    str r0, [sp, #8]",
    "    movs r6, #\\theta4",
    "    lsls r6, r6, #2",
    "    adds r6, r0, r6", // r6 = &theta from here on
    "    ldr r3, [r6, #4]",
    "    ldr r1, [sp, #0]",
    "    subs r1, r5, r1",
    "    asrs r7, r1, #31",
    "    subs r2, r5, r1",
    "    sbcs r3, r7", // (r2, r3) = θ[t − 24]
    "    ldrb r1, [r6, #{heads0}]",
    "    adds r1, r1, #1",
    "    cmp r1, #12",
    "    bne 4f",
    "    movs r1, #0",
    "4:",
    "    strb r1, [r6, #{heads0}]",
    "    lsls r1, r1, #3",
    "    adds r1, r1, r6",
    "    adds r1, #{rings}", // &rings[0][next]
    "    ldr r7, [r1, #0]",
    "    str r2, [r1, #0]",
    "    ldr r2, [r1, #4]",
    "    str r3, [r1, #4]", // (r7, r2) = the value displaced, θ[t − 48]
    "    ldr r1, [sp, #4]",
    "    subs r1, #48",
    "    lsls r3, r1, #30",
    "    bne 5f",
    // The displaced values move on up, as `cascade_up` and `cascade_rest` do: level K0 + j
    // (j ≥ 1) takes θ[index] when index is a multiple of 2^(j+1), and index drops by 24·2^j.
    // With q = index / 2^(j+1): q − 12 odd ends the climb, else q ← (q − 12)/2 (exact in
    // wrapping u32, the bits that matter are the low ones). r0 = q, r1 = &heads[j],
    // r2 = &rings[j], (r3, r7) = the value; lo θ[t − 16] waits in r12, lo θ[t + 2] in [sp].
    "    mov r12, r4",
    "    str r5, [sp, #0]",
    "    lsrs r0, r1, #2",
    "    mov r3, r7",
    "    mov r7, r2",
    "    mov r1, r6",
    "    adds r1, #{heads0} + 1",
    "    mov r2, r6",
    "    adds r2, #{rings} + 96",
    "24:",
    "    ldrb r4, [r1, #0]",
    "    adds r4, r4, #1",
    "    cmp r4, #12",
    "    bne 25f",
    "    movs r4, #0",
    "25:",
    "    strb r4, [r1, #0]",
    "    lsls r4, r4, #3",
    "    adds r4, r4, r2",
    "    ldr r5, [r4, #0]",
    "    str r3, [r4, #0]",
    "    mov r3, r5",
    "    ldr r5, [r4, #4]",
    "    str r7, [r4, #4]",
    "    mov r7, r5",
    "    subs r0, #12",
    "    lsrs r0, r0, #1",
    "    bcs 26f",
    "    adds r1, r1, #1",
    "    adds r2, #96",
    "    mov r4, r1",
    "    subs r4, r4, r6",
    "    cmp r4, #{heads0} + \\s",
    "    bne 24b",
    "26:",
    "    mov r4, r12",
    "    ldr r5, [sp, #0]",
    "    ldr r0, [sp, #8]",
    "5:",
    ".endm",
    // The strided levels for a sample whose count (before it) was odd, as `strided` does.
    // In: r0 = self, r4 = lo θ[t − 16], r5 = lo θ[t], r6 = &theta. Uses [sp] to [sp, #8].
    // Σ D2² += D2² (r1) and Σ D3² += D3² (r3) for the sums at r2: one multiply when |D| < 2^15,
    // else `add_square_wide`; l numbers the labels. Clobbers r1, r3, r7.
    ".macro APP_SQUARES l",
    "    asrs r7, r1, #15",
    "    adds r7, r7, #1",
    "    cmp r7, #1",
    "    bhi \\l\\()0f",
    "    muls r1, r1, r1",
    "    ldr r7, [r2, #0]",
    "    adds r7, r7, r1",
    "    str r7, [r2, #0]",
    "    bcc \\l\\()1f",
    "    adds r7, r2, #4",
    "    bl pico_imu_allan_carry",
    "    b \\l\\()1f",
    "\\l\\()0:",
    "    mov r7, r2",
    "    bl pico_imu_allan_add_square_wide",
    "\\l\\()1:", // Σ D3² += D3², the same way
    "    asrs r7, r3, #15",
    "    adds r7, r7, #1",
    "    cmp r7, #1",
    "    bhi \\l\\()2f",
    "    muls r3, r3, r3",
    "    ldr r7, [r2, #16]",
    "    adds r7, r7, r3",
    "    str r7, [r2, #16]",
    "    bcc \\l\\()3f",
    "    movs r7, #20",
    "    adds r7, r7, r2",
    "    bl pico_imu_allan_carry",
    "    b \\l\\()3f",
    "\\l\\()2:",
    "    mov r1, r3",
    "    mov r7, r2",
    "    adds r7, #16",
    "    bl pico_imu_allan_add_square_wide",
    "\\l\\()3:",
    ".endm",
    ".macro APP_STRIDED s, mag",
    // Sample 2's strided levels (its count t+1 was odd), as `strided` does: level K0 here when
    // it is full and narrow and its differences are below 2^16 (gate < 2^10), else `strided`.
    "    ldrb r1, [r6, #{full}]",
    "    ldrb r2, [r6, #{narrow}]",
    "    cmp r1, r2",
    "    bls 6f",
    "    mov r1, r2",
    "6:",
    "    cmp r1, #{k0}",
    "    bhi 17f",
    "    b 10f",
    "17:",
    ".if \\mag == 0",
    "    ldr r2, [r6, #{gate}]",
    "    lsrs r2, r2, #10",
    "    beq 18f",
    "    b 10f",
    ".endif",
    "18:",
    "    str r1, [sp, #4]", // fast = min(full, narrow)
    "    ldrb r2, [r6, #{heads0}]",
    "    mov r3, r6",
    "    adds r3, #{rings}", // &rings[0]
    "    APP_RING",
    "    APP_D23 r4, r7, r2",
    ".if \\mag",
    "    mov r4, r7", // lo θ[t − 2m]: level K0 + 1's θ[t − m]
    "    mov r2, r0",
    "    adds r2, #{k0sums}",
    "    APP_SQUARES 5",
    ".else",
    "    muls r1, r1, r1",
    "    muls r3, r3, r3",
    "    mov r4, r7", // lo θ[t − 2m]: level K0 + 1's θ[t − m]
    "    mov r2, r0",
    "    adds r2, #{k0sums}",
    "    ldr r7, [r2, #0]",
    "    adds r7, r7, r1",
    "    str r7, [r2, #0]",
    "    bcc 1f",
    "    adds r7, r2, #4",
    "    bl pico_imu_allan_carry",
    "1:",
    "    ldr r7, [r2, #16]",
    "    adds r7, r7, r3",
    "    str r7, [r2, #16]",
    "    bcc 2f",
    "    movs r7, #20",
    "    adds r7, r7, r2",
    "    bl pico_imu_allan_carry",
    "2:",
    ".endif",
    "    ldr r1, [r6, #{t}]",
    "    lsls r1, r1, #30",
    "    bmi 11f",
    // Levels K0 + j, j ≥ 1, as `strided_up` and `strided_rest` do: level K0 + j works when t is
    // a multiple of 2^(j+1) and it is full and narrow (k < fast), else `strided_general` takes
    // the rest. [sp] = j, [sp, #4] = fast, [sp, #8] = 2^(j+1) − 1; r4 = lo θ[t − m].
    "    movs r1, #1",
    "    str r1, [sp, #0]",
    "    movs r1, #3",
    "    str r1, [sp, #8]",
    "12:",
    "    ldr r1, [sp, #0]",
    "    ldr r2, [sp, #4]",
    "    adds r3, r1, #{k0}",
    "    cmp r3, r2",
    "    bhs 13f",
    "    adds r2, r6, r1",
    "    ldrb r2, [r2, #{heads0}]",
    "    movs r3, #96",
    "    muls r3, r1, r3",
    "    adds r3, r3, r6",
    "    adds r3, #{rings}", // &rings[j]
    "    APP_RING",
    "    APP_D23 r4, r7, r2",
    "    mov r4, r7",
    "    ldr r2, [sp, #0]",
    "    lsls r2, r2, #5",
    "    adds r2, r2, r0",
    "    adds r2, #{k0sums}", // &sums[K0 + j]
    "    APP_SQUARES 2",
    "    ldr r1, [sp, #0]",
    "    adds r1, r1, #1",
    "    cmp r1, #\\s",
    "    beq 11f",
    "    str r1, [sp, #0]",
    "    ldr r2, [sp, #8]",
    "    lsls r2, r2, #1",
    "    adds r2, r2, #1",
    "    str r2, [sp, #8]",
    "    ldr r3, [r6, #{t}]",
    "    tst r3, r2",
    "    beq 12b",
    "    b 11f",
    "13:",
    "    mov r1, r3",
    ".if \\mag",
    "    bl {mag_strided_tail}",
    ".else",
    "    bl {strided_tail}",
    ".endif",
    "    b 11f",
    "10:",
    "    mov r1, r4",
    ".if \\mag",
    "    bl {mag_strided}",
    ".else",
    "    bl {strided}",
    ".endif",
    "11:",
    ".endm",
    ".p2align 2",
    ".global pico_imu_allan_push_pair_small",
    ".type pico_imu_allan_push_pair_small,%function",
    ".thumb_func",
    "pico_imu_allan_push_pair_small:",
    "    push {{r4, r5, r6, r7, lr}}",
    // [sp] = lo θ[t − 24] (leaves for the cascade), [sp, #4] = t, [sp, #8] = lo θ[t + 2].
    "    sub sp, #12",
    "    movs r3, #{theta4}",
    "    lsls r3, r3, #2",
    "    adds r3, r0, r3",
    // Only in the steady, small state with an even count (else return 0, nothing changed):
    // 1 ≤ gate < 2^11, and |z| < gate ⟺ z + gate − 1 ≤ 2·(gate − 1) unsigned.
    "    ldr r4, [r3, #{offset}]",
    "    subs r1, r1, r4",
    "    subs r2, r2, r4", // z0, z1
    "    ldr r6, [r3, #{t}]",
    "    lsls r6, r6, #31",
    "    bne 90f",
    "    ldr r4, [r3, #{gate}]",
    "    lsrs r6, r4, #11",
    "    bne 90f",
    "    subs r5, r4, #1",
    "    bcc 90f", // gate = 0
    "    lsls r6, r5, #1",
    "    adds r7, r1, r5",
    "    cmp r7, r6",
    "    bhi 90f",
    "    adds r7, r2, r5",
    "    cmp r7, r6",
    "    bls 92f",
    "90:",
    "    movs r0, #0",
    "    add sp, #12",
    "    pop {{r4, r5, r6, r7, pc}}",
    "92:",
    "    ldrb r4, [r3, #{head}]",
    "    lsls r4, r4, #2",
    "    adds r4, r4, r3",
    "    subs r4, #{back}", // r4 = &base word h
    "    ldr r5, [r3, #0]",
    "    ldr r6, [r3, #4]",
    "    ldr r7, [r4, #0]",
    "    str r7, [sp, #0]",
    "    str r5, [r4, #0]",
    "    str r5, [r4, #96]", // θ[t] and its mirror
    "    asrs r7, r1, #31",
    "    adds r5, r5, r1",
    "    adcs r6, r7", // θ[t + 1] = (r5, r6)
    "    asrs r7, r2, #31",
    "    adds r1, r5, r2",
    "    adcs r7, r6", // θ[t + 2] = (r1, r7)
    "    str r1, [r3, #0]",
    "    str r7, [r3, #4]",
    "    str r1, [sp, #8]",
    "    ldr r6, [r3, #{t}]",
    "    ldr r7, [r3, #{t} + 4]",
    "    str r6, [sp, #4]",
    "    movs r1, #0",
    "    adds r6, r6, #2",
    "    adcs r7, r1",
    "    str r6, [r3, #{t}]",
    "    str r7, [r3, #{t} + 4]",
    "    ldrb r6, [r3, #{head}]",
    "    adds r6, r6, #2",
    "    cmp r6, #24",
    "    bne 3f",
    "    movs r6, #0",
    "3:",
    "    strb r6, [r3, #{head}]",
    // Sample 1: window at h + 1, θ = lo θ[t + 1] in r5.
    "    adds r2, r4, #4",
    "    APP_UNIT 0",
    "    str r5, [r2, #0]",
    "    str r5, [r2, #96]", // θ[t + 1] enters slot h + 1 and its mirror
    // Sample 2: window at h + 2.
    "    ldr r5, [sp, #8]",
    "    adds r2, r2, #4",
    "    APP_UNIT 0",
    "    APP_CASCADE {theta4}, {s}",
    "    APP_STRIDED {s}, 0",
    "    movs r0, #1",
    "    add sp, #12",
    "    pop {{r4, r5, r6, r7, pc}}",
    ".size pico_imu_allan_push_pair_small, . - pico_imu_allan_push_pair_small",
    // One sample: the same steps as the pair's first, then the cascade (even count) or the
    // strided levels (odd count). Used at the ends of bursts that do not split into pairs.
    // name: the symbol; theta4 and s: the engine's `THETA / 4` and S; mag = 1: `MagEngine`'s
    // routine (range-tested squares, any gate), 0: `DeviceEngine`'s (gate < 2^11).
    ".macro APP_SINGLE name, theta4, s, mag",
    ".pushsection .text.\\name,\"ax\",%progbits",
    ".p2align 2",
    ".global \\name",
    ".type \\name,%function",
    ".thumb_func",
    "\\name:",
    "    push {{r4, r5, r6, r7, lr}}",
    // [sp] = lo θ[t − 24], [sp, #4] = t, [sp, #8] scratch.
    "    sub sp, #12",
    "    movs r3, #\\theta4",
    "    lsls r3, r3, #2",
    "    adds r3, r0, r3",
    "    ldrb r4, [r3, #{head}]",
    "    lsls r4, r4, #2",
    "    adds r4, r4, r3",
    "    subs r4, #{back}",
    "    ldr r5, [r3, #0]",
    "    ldr r6, [r3, #4]",
    "    ldr r7, [r4, #0]",
    "    str r7, [sp, #0]",
    "    str r5, [r4, #0]",
    "    str r5, [r4, #96]",
    "    asrs r7, r1, #31",
    "    adds r5, r5, r1",
    "    adcs r6, r7",
    "    str r5, [r3, #0]",
    "    str r6, [r3, #4]",
    "    ldr r6, [r3, #{t}]",
    "    ldr r7, [r3, #{t} + 4]",
    "    str r6, [sp, #4]",
    "    movs r1, #0",
    "    adds r6, r6, #1",
    "    adcs r7, r1",
    "    str r6, [r3, #{t}]",
    "    str r7, [r3, #{t} + 4]",
    "    adds r2, r4, #4", // the window starts at slot h + 1 …
    "    ldrb r6, [r3, #{head}]",
    "    adds r6, r6, #1",
    "    cmp r6, #24",
    "    bne 3f",
    "    movs r6, #0",
    "    subs r2, #96", // … or at slot 0 when h + 1 wraps
    "3:",
    "    strb r6, [r3, #{head}]",
    "    APP_UNIT \\mag",
    "    ldr r1, [sp, #4]",
    "    lsls r2, r1, #31",
    "    beq 30f",
    "    b 31f",
    "30:", // even count: the cascade (θ[t − 24] from θ[t + 1])
    "    APP_CASCADE \\theta4, \\s",
    "    b 32f",
    "31:", // odd count: the strided levels
    "    movs r6, #\\theta4",
    "    lsls r6, r6, #2",
    "    adds r6, r0, r6",
    "    APP_STRIDED \\s, \\mag",
    "32:",
    "    add sp, #12",
    "    pop {{r4, r5, r6, r7, pc}}",
    ".size \\name, . - \\name",
    ".popsection",
    ".endm",
    "    APP_SINGLE pico_imu_allan_push_small, {theta4}, {s}, 0",
    "    APP_SINGLE pico_imu_allan_mag_push, {mag_theta4}, {mag_s}, 1",
    // [r7] (a Sum128) += r1² as a 64-bit square (any i32 r1); clobbers r1 and r7 only.
    ".type pico_imu_allan_add_square_wide,%function",
    ".thumb_func",
    "pico_imu_allan_add_square_wide:",
    "    push {{r2, r3, r4, r5, lr}}",
    "1:", // a = |r1| = h·2^16 + l: a² = h²·2^32 + l² + hl·2^17
    "    asrs r2, r1, #31",
    "    eors r1, r2",
    "    subs r1, r1, r2",
    "    lsrs r2, r1, #16",
    "    uxth r3, r1",
    "    mov r4, r2",
    "    muls r4, r3, r4",
    "    muls r2, r2, r2",
    "    muls r3, r3, r3",
    "    lsls r5, r4, #17",
    "    lsrs r4, r4, #15",
    "    adds r3, r3, r5",
    "    adcs r2, r4", // a² = (r2, r3)
    "    ldr r1, [r7, #0]",
    "    adds r1, r1, r3",
    "    str r1, [r7, #0]",
    "    ldr r1, [r7, #4]",
    "    adcs r1, r2",
    "    str r1, [r7, #4]",
    "    bcc 3f",
    "    ldr r1, [r7, #8]",
    "    adds r1, r1, #1",
    "    str r1, [r7, #8]",
    "    bcc 3f",
    "    ldr r1, [r7, #12]",
    "    adds r1, r1, #1",
    "    str r1, [r7, #12]",
    "3:",
    "    pop {{r2, r3, r4, r5, pc}}",
    ".size pico_imu_allan_add_square_wide, . - pico_imu_allan_add_square_wide",
    // Carry out of word 0 of a Sum128: r7 = &word 1; clobbers r1 only.
    ".type pico_imu_allan_carry,%function",
    ".thumb_func",
    "pico_imu_allan_carry:",
    "    ldr r1, [r7, #0]",
    "    adds r1, r1, #1",
    "    str r1, [r7, #0]",
    "    bcc 9f",
    "    ldr r1, [r7, #4]",
    "    adds r1, r1, #1",
    "    str r1, [r7, #4]",
    "    bcc 9f",
    "    ldr r1, [r7, #8]",
    "    adds r1, r1, #1",
    "    str r1, [r7, #8]",
    "9:",
    "    bx lr",
    ".size pico_imu_allan_carry, . - pico_imu_allan_carry",
    ".purgem APP_SINGLE",
    ".purgem APP_STRIDED",
    ".purgem APP_SQUARES",
    ".purgem APP_CASCADE",
    ".purgem APP_UNIT",
    ".purgem APP_CARRY_R",
    ".purgem APP_LEVEL_R",
    ".purgem APP_CARRY",
    ".purgem APP_RING",
    ".purgem APP_D23",
    ".purgem APP_LEVEL",
    ".popsection",
    theta4 = const THETA / 4,
    offset = const OFFSET - THETA,
    back = const THETA - BASE,
    t = const T - THETA,
    head = const HEAD - THETA,
    heads0 = const HEADS - THETA,
    full = const FULL - THETA,
    narrow = const NARROW - THETA,
    gate = const GATE - THETA,
    rings = const RINGS - THETA,
    k0 = const 4,
    k0sums = const 4 * 32,
    strided_tail = sym Engine::<8, 24, 12, 20>::strided_tail,
    s = const 20,
    strided = sym Engine::<8, 24, 12, 20>::strided,
    mag_theta4 = const MAG_THETA / 4,
    mag_s = const 18,
    mag_strided_tail = sym Engine::<8, 22, 12, 18>::strided_tail,
    mag_strided = sym Engine::<8, 22, 12, 18>::strided,
);
