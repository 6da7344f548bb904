//! The car-following laws of traffic: IDM acceleration, the Krauss safe
//! speed and Krauss dawdling.

use crate::params::TrafficParams;

/// IDM acceleration (Treiber et al. 2000) of a car at speed `v` with desired
/// speed `v0`, `gap` metres of free road to the next obstacle (bumper to
/// bumper; infinite on a free road) that moves at `v_lead`.
pub fn idm_accel(v: f64, v0: f64, gap: f64, v_lead: f64, p: &TrafficParams) -> f64 {
    let r = v / v0.max(0.1);
    // powf is slow; delta is 4 unless a scenario says otherwise.
    let free = 1.0
        - if p.idm_delta == 4.0 {
            (r * r) * (r * r)
        } else {
            r.powf(p.idm_delta)
        };
    if !gap.is_finite() {
        return p.accel * free;
    }
    if gap <= 0.0 {
        return -p.emergency_decel;
    }
    let dv = v - v_lead;
    let s_star = p.min_gap + (v * p.headway + v * dv / (2.0 * (p.accel * p.decel).sqrt())).max(0.0);
    let ratio = s_star / gap;
    p.accel * (free - ratio * ratio)
}

/// Improved IDM (Treiber and Kesting, *Traffic Flow Dynamics*, 2013,
/// section 11.3.7) with the same parameters as [`idm_accel`]. Plain IDM
/// mixes its free-road and interaction terms, so a follower whose desired
/// speed is above its leader's speed hangs back at a gap of
/// `s* / sqrt(1 - (v/v0)^delta)` rather than `s*`: behind a leader at 0.9 of
/// its desired speed, 1.7 times the desired gap. Platoons then spread to
/// 2 to 3 s headways and a lane carries at most about 0.5 cars/s. The
/// improved model keeps the equilibrium gap at `s*` whatever the speed and
/// is IDM otherwise (the same free-road acceleration, the same braking when
/// the gap is below `s*`).
pub fn iidm_accel(v: f64, v0: f64, gap: f64, v_lead: f64, p: &TrafficParams) -> f64 {
    iidm_accel_with(iidm_free_accel(v, v0, p), v, v0, gap, v_lead, p)
}

/// The improved IDM's free-road acceleration: IDM's `a (1 - (v/v0)^delta)`
/// below the desired speed, a relaxation with at most `b` above it. Near
/// `v0` it is small (`a / 4` at 0.93 `v0` with delta 4), so a car that
/// dawdles below its desired speed every step, as Krauss drivers do,
/// cruises at about `(1 - sigma / 2)^(1/delta)` of it: 0.93 with SUMO's
/// sigma of 0.5.
pub fn iidm_free_accel(v: f64, v0: f64, p: &TrafficParams) -> f64 {
    let v0 = v0.max(0.1);
    if v <= v0 {
        let r = v / v0;
        let power = if p.idm_delta == 4.0 {
            (r * r) * (r * r)
        } else {
            r.powf(p.idm_delta)
        };
        p.accel * (1.0 - power)
    } else {
        -p.decel * (1.0 - (v0 / v).powf(p.accel * p.idm_delta / p.decel))
    }
}

/// Krauss's free-road acceleration (SUMO's `MSCFModel::maxNextSpeed`): the
/// full `a` until the desired speed, which it reaches within the step
/// `dt`, and back down to it with at most `b`. Dawdling then leaves a car
/// on average `sigma a dt / 2` below its desired speed (0.13 m/s), as in
/// SUMO, not 7 % below as under IDM's free-road term.
pub fn krauss_free_accel(v: f64, v0: f64, dt: f64, p: &TrafficParams) -> f64 {
    ((v0 - v) / dt).clamp(-p.decel, p.accel)
}

/// The improved IDM with a given free-road acceleration `a_free` (of
/// [`iidm_free_accel`] in [`iidm_accel`], or [`krauss_free_accel`]).
pub fn iidm_accel_with(
    a_free: f64,
    v: f64,
    v0: f64,
    gap: f64,
    v_lead: f64,
    p: &TrafficParams,
) -> f64 {
    let v0 = v0.max(0.1);
    if !gap.is_finite() {
        return a_free;
    }
    if gap <= 0.0 {
        return -p.emergency_decel;
    }
    let dv = v - v_lead;
    let s_star = p.min_gap + (v * p.headway + v * dv / (2.0 * (p.accel * p.decel).sqrt())).max(0.0);
    let z = s_star / gap;
    if v <= v0 {
        if z >= 1.0 {
            p.accel * (1.0 - z * z)
        } else if a_free <= 0.0 {
            0.0
        } else {
            a_free * (1.0 - z.powf(2.0 * p.accel / a_free))
        }
    } else if z >= 1.0 {
        a_free + p.accel * (1.0 - z * z)
    } else {
        a_free
    }
}

/// Krauss safe speed (SUMO): the fastest a follower may go so that it can
/// still stop behind a leader `gap` metres ahead moving at `v_lead`, if the
/// leader brakes at `decel`, with reaction time `tau`.
pub fn krauss_safe_speed(gap: f64, v_lead: f64, tau: f64, decel: f64) -> f64 {
    let tb = tau * decel;
    let under = tb * tb + v_lead * v_lead + 2.0 * decel * gap.max(0.0);
    (-tb + under.sqrt()).max(0.0)
}

/// Krauss dawdling: the speed after a random slowdown of up to
/// `sigma * accel * dt`, given a uniform draw `u` in `[0, 1)`.
pub fn dawdle(v: f64, u: f64, dt: f64, p: &TrafficParams) -> f64 {
    (v - p.sigma * p.accel * dt * u).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> TrafficParams {
        TrafficParams {
            headway: 1.0,
            ..TrafficParams::default()
        }
    }

    #[test]
    fn idm_free_road() {
        let p = p();
        // At rest: full acceleration.
        assert!((idm_accel(0.0, 20.0, f64::INFINITY, 0.0, &p) - 2.6).abs() < 1e-12);
        // At the desired speed: none.
        assert!(idm_accel(20.0, 20.0, f64::INFINITY, 0.0, &p).abs() < 1e-12);
        // Half the desired speed: a (1 - 1/16).
        assert!((idm_accel(10.0, 20.0, f64::INFINITY, 0.0, &p) - 2.6 * 15.0 / 16.0).abs() < 1e-12);
        // Faster than desired: it slows down.
        assert!(idm_accel(22.0, 20.0, f64::INFINITY, 0.0, &p) < 0.0);
    }

    #[test]
    fn idm_interaction_term() {
        let p = p();
        // Standing still at exactly s0 behind a stopped car: balance.
        assert!(idm_accel(0.0, 20.0, 2.5, 0.0, &p).abs() < 1e-12);
        // At half of s0: a (1 - 4).
        assert!((idm_accel(0.0, 20.0, 1.25, 0.0, &p) - -7.8).abs() < 1e-12);
        // Hand-computed: v = 10, v0 = 20, gap 30, leader 5 m/s:
        // s* = 2.5 + 10 + 10*5/(2 sqrt(2.6*4.5)) = 12.5 + 50/6.8411 = 19.8088
        // a = 2.6 (1 - 1/16 - (19.8088/30)^2) = 1.3041
        let a = idm_accel(10.0, 20.0, 30.0, 5.0, &p);
        let s_star = 12.5 + 50.0 / (2.0 * (2.6_f64 * 4.5).sqrt());
        let want = 2.6 * (1.0 - 1.0 / 16.0 - (s_star / 30.0).powi(2));
        assert!((a - want).abs() < 1e-12 && (a - 1.3041).abs() < 1e-3, "{a}");
        // Closing fast on a stopped obstacle: braking, harder when nearer.
        let far = idm_accel(20.0, 20.0, 80.0, 0.0, &p);
        let near = idm_accel(20.0, 20.0, 40.0, 0.0, &p);
        assert!(far < 0.0 && near < far);
        assert_eq!(idm_accel(5.0, 20.0, -1.0, 0.0, &p), -9.0);
    }

    #[test]
    fn iidm_keeps_the_desired_gap_below_the_desired_speed() {
        let p = p();
        // Free road: the same as IDM below v0; above v0 it relaxes with
        // at most b.
        for v in [0.0, 10.0, 19.0, 20.0] {
            let want = idm_accel(v, 20.0, f64::INFINITY, 0.0, &p);
            assert!((iidm_accel(v, 20.0, f64::INFINITY, 0.0, &p) - want).abs() < 1e-12);
        }
        let over = iidm_accel(25.0, 20.0, f64::INFINITY, 0.0, &p);
        assert!(over < 0.0 && over > -4.5, "{over}");
        // At 16 m/s behind a leader at 16 m/s exactly s* = 2.5 + 16 = 18.5 m
        // back, with a desired speed of 20: IIDM holds (0 acceleration),
        // IDM brakes at a 0.8^4 = 1.06 m/s², as its free-road term is only
        // 1 - 0.8^4.
        assert!(iidm_accel(16.0, 20.0, 18.5, 16.0, &p).abs() < 1e-12);
        assert!((idm_accel(16.0, 20.0, 18.5, 16.0, &p) + 2.6 * 0.8_f64.powi(4)).abs() < 1e-12);
        // Below s* both brake the same: a (1 - z^2).
        let (a, b) = (
            iidm_accel(16.0, 20.0, 10.0, 16.0, &p),
            2.6 * (1.0 - 1.85_f64.powi(2)),
        );
        assert!((a - b).abs() < 1e-12, "{a} {b}");
        // A wider gap than s*: it closes it, gently.
        let a = iidm_accel(16.0, 20.0, 40.0, 16.0, &p);
        assert!(a > 0.0 && a < 2.6 * (1.0 - 0.8_f64.powi(4)), "{a}");
        assert_eq!(iidm_accel(5.0, 20.0, -1.0, 0.0, &p), -9.0);
    }

    #[test]
    fn krauss_free_road_reaches_the_desired_speed_within_the_step() {
        let p = p();
        // Full a from standstill and until the last step before v0.
        assert_eq!(krauss_free_accel(0.0, 20.0, 0.2, &p), 2.6);
        assert_eq!(krauss_free_accel(19.0, 20.0, 0.2, &p), 2.6);
        // The last step lands on v0: (20 - 19.9) / 0.2 = 0.5 m/s².
        assert!((krauss_free_accel(19.9, 20.0, 0.2, &p) - 0.5).abs() < 1e-9);
        assert_eq!(krauss_free_accel(20.0, 20.0, 0.2, &p), 0.0);
        // Above v0 it slows with at most b.
        assert_eq!(krauss_free_accel(25.0, 20.0, 0.2, &p), -4.5);
        // IDM's term near v0 is much smaller: a (1 - 0.95^4) = 0.48 m/s².
        let idm = iidm_free_accel(19.0, 20.0, &p);
        assert!(
            (idm - 2.6 * (1.0 - 0.95_f64.powi(4))).abs() < 1e-12,
            "{idm}"
        );
        // Behind a leader the interaction term is IIDM's either way: at s*
        // and equal speeds, hold.
        assert!(iidm_accel_with(2.6, 16.0, 20.0, 18.5, 16.0, &p).abs() < 1e-12);
        assert!(iidm_accel_with(2.6, 16.0, 20.0, 10.0, 16.0, &p) < -4.0);
    }

    #[test]
    fn krauss_safe_speed_values() {
        // No gap and a stopped leader: must stop.
        assert_eq!(krauss_safe_speed(0.0, 0.0, 1.0, 4.5), 0.0);
        // Hand-computed: gap 20, leader 10, tau 1, b 4.5:
        // -4.5 + sqrt(20.25 + 100 + 180) = 12.8275
        let v = krauss_safe_speed(20.0, 10.0, 1.0, 4.5);
        assert!((v - (-4.5 + 300.25_f64.sqrt())).abs() < 1e-12);
        // The follower at v_safe stops behind the leader's stopping point:
        // v tau + v^2/(2b) <= gap + v_lead^2/(2b).
        let lhs = v * 1.0 + v * v / 9.0;
        assert!(lhs <= 20.0 + 100.0 / 9.0 + 1e-9);
    }

    #[test]
    fn dawdling_bounds() {
        let p = p();
        assert_eq!(dawdle(10.0, 0.0, 0.2, &p), 10.0);
        // u -> 1: slows by sigma * a * dt = 0.5 * 2.6 * 0.2 = 0.26 m/s.
        assert!((dawdle(10.0, 0.999_999, 0.2, &p) - 9.74).abs() < 1e-5);
        assert_eq!(dawdle(0.1, 0.9, 0.2, &p), 0.0);
    }
}
