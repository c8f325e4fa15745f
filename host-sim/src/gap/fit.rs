//! Levenberg-Marquardt with a forward-difference Jacobian and box bounds, for fits of a few
//! parameters where each residual evaluation is a closed-loop simulation.
//!
//! The simulation of a loop with Hall quantisation is not smooth in its parameters (a change
//! moves the chatter), so the difference step is a fixed share of each parameter's range rather
//! than of its value: the Jacobian then sees the trend, not the chatter. A coarse scan over the
//! first parameter picks the start, so a fit is not caught in the local minimum of a dead band.

use nalgebra::{DMatrix, DVector};

/// One fitted parameter: name, unit, bounds and the difference step.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    pub name: &'static str,
    pub lo: f64,
    pub hi: f64,
    /// Start value.
    pub start: f64,
    /// Forward-difference step.
    pub step: f64,
}

impl ParamSpec {
    /// This spec started at `start`, kept within its bounds.
    pub fn started_at(mut self, start: f64) -> ParamSpec {
        self.start = start.clamp(self.lo, self.hi);
        self
    }
}

/// The result of a fit.
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    pub params: Vec<f64>,
    pub cost: f64,
    /// Standard error of each parameter from the Gauss-Newton covariance (NaN if singular).
    pub std_err: Vec<f64>,
    pub evaluations: usize,
}

/// Options: scan points over the first parameter, LM iterations.
#[derive(Debug, Clone, Copy)]
pub struct FitOptions {
    pub scan: usize,
    pub iterations: usize,
    /// Rounds of coordinate polish after LM.
    pub polish: usize,
    /// Threads the Jacobian's columns are simulated on (1: in the caller's thread). The
    /// result is the same for any count: each column is its own simulation.
    pub jacobian_threads: usize,
    /// Hold a parameter at its bound out of a step that would push it further out (solve
    /// the step for the others alone), instead of clamping it after the step: clamping
    /// leaves the others with a step that was solved for a move the bound forbids. A
    /// parameter that starts at its bound and whose gradient points out of the range (the
    /// log's lag at 0 beside a table that is off) otherwise spoils every step.
    pub hold_at_bounds: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            scan: 6,
            iterations: 8,
            polish: 2,
            jacobian_threads: 1,
            hold_at_bounds: false,
        }
    }
}

fn cost_of(r: &[f64]) -> f64 {
    let c: f64 = r.iter().map(|v| v * v).sum();
    if c.is_finite() { c } else { f64::INFINITY }
}

/// Minimise `||residual(p)||^2` within the bounds. `tick` is called after every evaluation.
pub fn levenberg_marquardt(
    specs: &[ParamSpec],
    opts: FitOptions,
    residual: &(dyn Fn(&[f64]) -> Vec<f64> + Sync),
    tick: &(dyn Fn() + Sync),
) -> FitResult {
    let np = specs.len();
    let clamp = |p: &mut [f64]| {
        for (v, s) in p.iter_mut().zip(specs) {
            *v = v.clamp(s.lo, s.hi);
        }
    };
    let mut evals = 0usize;
    let eval = |p: &[f64], evals: &mut usize| {
        *evals += 1;
        let r = residual(p);
        tick();
        r
    };
    let mut p: Vec<f64> = specs.iter().map(|s| s.start).collect();
    clamp(&mut p);
    let mut r = eval(&p, &mut evals);
    let mut cost = cost_of(&r);
    // Coarse scan of the first parameter (geometric from a tenth of the range up).
    if np > 0 && opts.scan > 1 {
        let s = &specs[0];
        let lo = (s.lo + 0.02 * (s.hi - s.lo)).max(s.lo);
        for k in 0..opts.scan {
            let frac = k as f64 / (opts.scan - 1) as f64;
            let mut q = p.clone();
            q[0] = lo + (s.hi - lo) * frac * frac;
            let rq = eval(&q, &mut evals);
            let cq = cost_of(&rq);
            if cq < cost {
                p = q;
                r = rq;
                cost = cq;
            }
        }
    }
    let mut lambda = 1e-2;
    let mut jac = DMatrix::<f64>::zeros(r.len(), np);
    for _ in 0..opts.iterations {
        if np == 0 || r.is_empty() {
            break;
        }
        jac = DMatrix::<f64>::zeros(r.len(), np);
        // Column j: (step, residual there).
        let column = |j: usize| {
            let mut q = p.clone();
            let mut h = specs[j].step;
            if q[j] + h > specs[j].hi {
                h = -h;
            }
            q[j] += h;
            let rq = residual(&q);
            tick();
            (h, rq)
        };
        let columns: Vec<(f64, Vec<f64>)> = if opts.jacobian_threads > 1 && np > 1 {
            let per = np.div_ceil(opts.jacobian_threads);
            std::thread::scope(|s| {
                let handles: Vec<_> = (0..np)
                    .step_by(per)
                    .map(|first| {
                        let column = &column;
                        s.spawn(move || {
                            (first..(first + per).min(np))
                                .map(column)
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .flat_map(|h| {
                        h.join()
                            .unwrap_or_else(|e| std::panic::resume_unwind(e))
                            .into_iter()
                    })
                    .collect::<Vec<_>>()
            })
        } else {
            (0..np).map(column).collect()
        };
        evals += np;
        for (j, (h, rq)) in columns.iter().enumerate() {
            for i in 0..r.len().min(rq.len()) {
                jac[(i, j)] = (rq[i] - r[i]) / h;
            }
        }
        let rv = DVector::from_column_slice(&r);
        let jtj = jac.transpose() * &jac;
        let jtr = jac.transpose() * rv;
        // The damped Gauss-Newton step, with the parameters held at their bounds (those the
        // step would push out) taken out of the system when `hold_at_bounds`.
        let step = |jtj: &DMatrix<f64>, jtr: &DVector<f64>, lambda: f64, p: &[f64]| {
            let mut held = vec![false; np];
            loop {
                let mut a = jtj.clone();
                let mut b = -jtr.clone();
                for d in 0..np {
                    a[(d, d)] += lambda * jtj[(d, d)].max(1e-12);
                    if held[d] {
                        for k in 0..np {
                            a[(d, k)] = 0.0;
                            a[(k, d)] = 0.0;
                        }
                        a[(d, d)] = 1.0;
                        b[d] = 0.0;
                    }
                }
                let delta = a.lu().solve(&b)?;
                let mut more = false;
                if opts.hold_at_bounds {
                    for (d, s) in specs.iter().enumerate() {
                        let out =
                            (p[d] <= s.lo && delta[d] < 0.0) || (p[d] >= s.hi && delta[d] > 0.0);
                        if out && !held[d] {
                            held[d] = true;
                            more = true;
                        }
                    }
                }
                if !more {
                    return Some(delta);
                }
            }
        };
        let mut improved = false;
        for _ in 0..4 {
            let Some(delta) = step(&jtj, &jtr, lambda, &p) else {
                lambda *= 10.0;
                continue;
            };
            let mut q: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            clamp(&mut q);
            let rq = eval(&q, &mut evals);
            let cq = cost_of(&rq);
            if cq < cost {
                let gain = (cost - cq) / cost.max(1e-300);
                p = q;
                r = rq;
                cost = cq;
                lambda = (lambda * 0.3).max(1e-6);
                improved = gain > 1e-4;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    // Polish: coordinate moves of a difference step and a third of one, which the Jacobian
    // of a chattering loop can miss.
    for _ in 0..opts.polish {
        let mut moved = false;
        for j in 0..np {
            for frac in [1.0, -1.0, 1.0 / 3.0, -1.0 / 3.0] {
                let mut q = p.clone();
                q[j] += frac * specs[j].step;
                clamp(&mut q);
                if q[j] == p[j] {
                    continue;
                }
                let rq = eval(&q, &mut evals);
                let cq = cost_of(&rq);
                if cq < cost {
                    p = q;
                    r = rq;
                    cost = cq;
                    moved = true;
                    break;
                }
            }
        }
        if !moved {
            break;
        }
    }
    let dof = (r.len() as f64 - np as f64).max(1.0);
    let sigma2 = cost / dof;
    let jtj = jac.transpose() * &jac;
    let std_err = match jtj.try_inverse() {
        Some(inv) => (0..np)
            .map(|j| (inv[(j, j)] * sigma2).abs().sqrt())
            .collect(),
        None => vec![f64::NAN; np],
    };
    FitResult {
        params: p,
        cost,
        std_err,
        evaluations: evals,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_parameters_of_a_known_curve() {
        let t: Vec<f64> = (0..50).map(|k| k as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * (-0.7 * t).exp()).collect();
        let res = |p: &[f64]| -> Vec<f64> {
            t.iter()
                .zip(&y)
                .map(|(t, y)| p[0] * (-p[1] * t).exp() - y)
                .collect()
        };
        let specs = [
            ParamSpec {
                name: "a",
                lo: 0.0,
                hi: 5.0,
                start: 1.0,
                step: 1e-4,
            },
            ParamSpec {
                name: "k",
                lo: 0.0,
                hi: 3.0,
                start: 0.2,
                step: 1e-4,
            },
        ];
        let fit_on = |jacobian_threads| {
            levenberg_marquardt(
                &specs,
                FitOptions {
                    scan: 5,
                    iterations: 40,
                    polish: 0,
                    jacobian_threads,
                    hold_at_bounds: false,
                },
                &res,
                &|| {},
            )
        };
        let fit = fit_on(1);
        assert!((fit.params[0] - 2.0).abs() < 1e-3, "{:?}", fit.params);
        assert!((fit.params[1] - 0.7).abs() < 1e-3, "{:?}", fit.params);
        // The Jacobian's columns on threads (one each, and more threads than columns) give
        // the same fit to the last bit, with the same count of evaluations.
        for threads in [2, 5] {
            assert_eq!(fit_on(threads), fit, "{threads} threads");
        }
    }

    /// A line y = 2x - 5 fitted with its offset bounded to [0, 10] from the bound: the best
    /// line there has the offset at 0 and the slope 2 - 5 (sum x) / (sum x^2). Holding the
    /// offset at its bound, one iteration finds that slope; clamping the offset after a step
    /// solved for -5 leaves the slope's step wrong.
    #[test]
    fn a_parameter_held_at_its_bound_leaves_the_others_the_right_step() {
        let x: Vec<f64> = (0..=10).map(f64::from).collect();
        let res = |p: &[f64]| -> Vec<f64> {
            x.iter()
                .map(|x| p[0] * x + p[1] - (2.0 * x - 5.0))
                .collect()
        };
        let specs = [
            ParamSpec {
                name: "slope",
                lo: 0.0,
                hi: 10.0,
                start: 1.0,
                step: 1e-6,
            },
            ParamSpec {
                name: "offset",
                lo: 0.0,
                hi: 10.0,
                start: 0.0,
                step: 1e-6,
            },
        ];
        let fit = |hold_at_bounds| {
            levenberg_marquardt(
                &specs,
                FitOptions {
                    scan: 0,
                    iterations: 1,
                    polish: 0,
                    jacobian_threads: 1,
                    hold_at_bounds,
                },
                &res,
                &|| {},
            )
        };
        let best = 2.0 - 5.0 * 55.0 / 385.0;
        let (held, clamped) = (fit(true), fit(false));
        assert_eq!(held.params[1], 0.0);
        assert!(
            (held.params[0] - best).abs() < 0.02 * best,
            "{:?}",
            held.params
        );
        println!(
            "held {:?} {:.2}, clamped {:?} {:.2}",
            held.params, held.cost, clamped.params, clamped.cost
        );
        assert!(clamped.cost > held.cost, "{} {}", clamped.cost, held.cost);
        assert!(
            (clamped.params[0] - best).abs() > 0.05 * best,
            "{:?}",
            clamped.params
        );
    }
}
