//! The planner: the set of cached nodes (and their finest cached levels) that the model
//! predicts fastest among those whose working set fits the memory budget.
//!
//! - **Exhaustive** when there are at most [`SearchOptions::exhaustive_limit`] candidates: every
//!   subset is predicted; the result is the model's optimum over subsets cached at all levels.
//! - **Local search** otherwise: a greedy pass adds the node that lowers the predicted time the
//!   most until none does; then best-improvement moves (add, remove, or swap one node) repeat
//!   until no move improves. The result is a local optimum: no single addition, removal or swap
//!   predicts faster within the budget. `none`, `outputs` and `all` are evaluated too and win if
//!   better, so the plan is never predicted slower than any fixed strategy that fits.
//! - **Level thresholds** (beyond the paper): for each cached node in turn, the finest cached
//!   level `min_level` is chosen from `0..=max_level` by coordinate descent (finer requests
//!   evaluate the node directly), kept where the model predicts a gain. The descent runs from
//!   the searched plan and from a second start, the materials' outputs cached from the one level
//!   that predicts fastest: outputs cached for coarse requests only (secondary bounces) often
//!   win where the searches above, which add nodes cached at every level, see only losses.
//!
//! Candidates are the nodes marked cacheable that some stream reaches.

use std::time::Instant;

use crate::error::{PlanError, Result};
use crate::model::{Model, PlanSpec, Prediction};

/// Search settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchOptions {
    /// Largest working set allowed, in bytes.
    pub budget_bytes: f64,
    /// Exhaustive search up to this many candidates.
    pub exhaustive_limit: usize,
    /// Also choose per-node level thresholds.
    pub thresholds: bool,
}

impl SearchOptions {
    /// Defaults for a budget: exhaustive up to 12 candidates, thresholds on.
    pub fn with_budget(budget_bytes: f64) -> SearchOptions {
        SearchOptions { budget_bytes, exhaustive_limit: 12, thresholds: true }
    }
}

/// The planner's answer.
#[derive(Clone, Debug)]
pub struct SearchResult {
    /// The chosen plan.
    pub plan: PlanSpec,
    /// Its prediction.
    pub prediction: Prediction,
    /// `"exhaustive"` or `"local search"` (with `" + thresholds"` when thresholds were chosen).
    pub method: String,
    /// Candidate nodes.
    pub candidates: usize,
    /// Plans the model predicted.
    pub plans_evaluated: u64,
    /// Seconds the search took.
    pub seconds: f64,
}

/// The cacheable nodes some stream reaches: `(graph, node)`.
pub fn candidates(model: &Model) -> Vec<(usize, usize)> {
    let p = model.profile();
    let mut reached: Vec<Vec<bool>> = p.graphs.iter().map(|g| vec![false; g.nodes.len()]).collect();
    for s in &p.streams {
        let g = s.graph as usize;
        let mut stack: Vec<u32> = s.outputs.clone();
        while let Some(n) = stack.pop() {
            if !std::mem::replace(&mut reached[g][n as usize], true) {
                stack.extend(p.graphs[g].nodes[n as usize].inputs.iter().copied());
            }
        }
    }
    let mut out = Vec::new();
    for (g, graph) in p.graphs.iter().enumerate() {
        for (n, node) in graph.nodes.iter().enumerate() {
            if node.cacheable && node.exact_when_cached && reached[g][n] {
                out.push((g, n));
            }
        }
    }
    out
}

struct Search<'m, 'p> {
    model: &'m Model<'p>,
    budget: f64,
    evaluated: u64,
}

impl Search<'_, '_> {
    /// Predicted seconds, or `None` when the plan's working set exceeds the budget.
    fn score(&mut self, plan: &PlanSpec) -> Option<(f64, Prediction)> {
        self.evaluated += 1;
        let p = self.model.predict(plan);
        (p.peak_bytes <= self.budget).then_some((p.render_s, p))
    }
}

/// Finds the plan the model predicts fastest within the budget (see the module documentation).
pub fn search(model: &Model, opts: SearchOptions) -> Result<SearchResult> {
    if !(opts.budget_bytes.is_finite() && opts.budget_bytes >= 0.0) {
        return Err(PlanError::Settings(format!(
            "the budget must be a non-negative number of bytes, got {}",
            opts.budget_bytes
        )));
    }
    let start = Instant::now();
    let profile = model.profile();
    let cands = candidates(model);
    let mut s = Search { model, budget: opts.budget_bytes, evaluated: 0 };
    let none = PlanSpec::none(profile);
    let (mut best_t, mut best_p) = s.score(&none).expect("caching nothing needs no memory");
    let mut best = none.clone();
    let consider = |s: &mut Search, plan: PlanSpec, best: &mut PlanSpec, bt: &mut f64, bp: &mut Prediction| {
        if let Some((t, p)) = s.score(&plan) {
            if t < *bt {
                (*best, *bt, *bp) = (plan, t, p);
            }
        }
    };
    for fixed in [PlanSpec::outputs(profile), PlanSpec::all(profile)] {
        consider(&mut s, fixed, &mut best, &mut best_t, &mut best_p);
    }
    let method;
    if cands.len() <= opts.exhaustive_limit {
        method = "exhaustive";
        for mask in 1u64..(1u64 << cands.len()) {
            let mut plan = none.clone();
            for (k, &(g, n)) in cands.iter().enumerate() {
                if mask >> k & 1 == 1 {
                    plan.cached[g][n] = Some(0);
                }
            }
            consider(&mut s, plan, &mut best, &mut best_t, &mut best_p);
        }
    } else {
        method = "local search";
        // Greedy additions from nothing.
        let mut cur = none.clone();
        let mut cur_t = s.score(&cur).map_or(f64::INFINITY, |x| x.0);
        loop {
            let mut step: Option<(PlanSpec, f64)> = None;
            for &(g, n) in &cands {
                if cur.cached[g][n].is_some() {
                    continue;
                }
                let mut next = cur.clone();
                next.cached[g][n] = Some(0);
                if let Some((t, _)) = s.score(&next) {
                    if t < step.as_ref().map_or(cur_t, |x| x.1) {
                        step = Some((next, t));
                    }
                }
            }
            match step {
                Some((next, t)) => (cur, cur_t) = (next, t),
                None => break,
            }
        }
        // Best-improvement flips and swaps from the greedy plan and from the best fixed one.
        for start_plan in [cur, best.clone()] {
            let (plan, _) = improve(&mut s, start_plan, &cands);
            consider(&mut s, plan, &mut best, &mut best_t, &mut best_p);
        }
    }
    let mut method = method.to_string();
    if opts.thresholds {
        let before = best_t;
        let max = profile.cache.max_level;
        if best.count() > 0 {
            (best, best_t, best_p) = descend_levels(&mut s, best, best_t, best_p, max);
        }
        // A second start: the materials' outputs cached from one level, the fastest such level,
        // their levels then descended. Searches over nodes cached at every level never reach
        // it (cached from level 0, the outputs fill fine tiles for first hits a pixel's samples
        // already share, and lose), yet cached only for coarse requests (secondary bounces)
        // they won: poster_wall 0.30 s against 0.40 uncached, marble 0.26 against 0.31,
        // predicted and measured. Every level is tried (a prediction each): the descent moves
        // one node's level at a time, and from the middle level it stopped short of moving all
        // together (marble at 32², 64 spp: 0.04948 s against 0.04936 for outputs from level 11).
        // Only outputs the planner may choose ([`PlanSpec::outputs_from`]).
        let mut start: Option<(PlanSpec, f64, Prediction)> = None;
        let any = PlanSpec::outputs_from(profile, 0).count() > 0;
        for level in (0..=max).filter(|_| any) {
            let outputs = PlanSpec::outputs_from(profile, level);
            if let Some((t, p)) = s.score(&outputs) {
                if start.as_ref().is_none_or(|x| t < x.1) {
                    start = Some((outputs, t, p));
                }
            }
        }
        if let Some((outputs, t, p)) = start {
            let (plan, t, p) = descend_levels(&mut s, outputs, t, p, max);
            if t < best_t {
                (best, best_t, best_p) = (plan, t, p);
            }
        }
        if best_t < before {
            method.push_str(" + thresholds");
        }
    }
    Ok(SearchResult {
        plan: best,
        prediction: best_p,
        method,
        candidates: cands.len(),
        plans_evaluated: s.evaluated,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Coordinate descent on the finest cached level of each cached node of `best` (every level
/// tried for one node while the others stay), up to three sweeps or until no change lowers the
/// predicted time; the plan, its time and its prediction.
fn descend_levels(
    s: &mut Search,
    mut best: PlanSpec,
    mut best_t: f64,
    mut best_p: Prediction,
    max: u8,
) -> (PlanSpec, f64, Prediction) {
    let cached: Vec<(usize, usize)> = best
        .cached
        .iter()
        .enumerate()
        .flat_map(|(g, nodes)| nodes.iter().enumerate().filter(|(_, c)| c.is_some()).map(move |(n, _)| (g, n)))
        .collect();
    for _sweep in 0..3 {
        let mut changed = false;
        for &(g, n) in &cached {
            let Some(current) = best.cached[g][n] else { continue };
            for min in 0..=max {
                if min == current {
                    continue;
                }
                let mut next = best.clone();
                next.cached[g][n] = Some(min);
                if let Some((t, p)) = s.score(&next) {
                    if t < best_t * (1.0 - 1e-9) {
                        (best, best_t, best_p) = (next, t, p);
                        changed = true;
                    }
                }
            }
        }
        if !changed {
            break;
        }
    }
    (best, best_t, best_p)
}

/// Best-improvement local search over single additions, removals and swaps.
fn improve(s: &mut Search, mut cur: PlanSpec, cands: &[(usize, usize)]) -> (PlanSpec, f64) {
    let mut cur_t = s.score(&cur).map_or(f64::INFINITY, |x| x.0);
    loop {
        let mut step: Option<(PlanSpec, f64)> = None;
        let try_plan = |s: &mut Search, next: PlanSpec, step: &mut Option<(PlanSpec, f64)>| {
            if let Some((t, _)) = s.score(&next) {
                if t < step.as_ref().map_or(cur_t, |x| x.1) * (1.0 - 1e-9) {
                    *step = Some((next, t));
                }
            }
        };
        for &(g, n) in cands {
            let mut next = cur.clone();
            next.cached[g][n] = if cur.cached[g][n].is_some() { None } else { Some(0) };
            try_plan(s, next, &mut step);
        }
        if step.is_none() {
            for &(g, n) in cands.iter().filter(|&&(g, n)| cur.cached[g][n].is_some()) {
                for &(h, m) in cands.iter().filter(|&&(h, m)| cur.cached[h][m].is_none()) {
                    let mut next = cur.clone();
                    next.cached[g][n] = None;
                    next.cached[h][m] = Some(0);
                    try_plan(s, next, &mut step);
                }
            }
        }
        match step {
            Some((next, t)) => (cur, cur_t) = (next, t),
            None => return (cur, cur_t),
        }
    }
}
