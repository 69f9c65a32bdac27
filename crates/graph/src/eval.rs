//! Filtered evaluation: [`EvalScratch`] (per-thread, preallocated), [`NodeOverride`] (the seam
//! where a tile cache replaces a node by a lookup), and the evaluation entry points on
//! [`Graph`].
//!
//! Evaluation is demand-driven over a precomputed topological order: walking it backwards
//! marks what the requested outputs need, asking the override for each needed node first (a
//! node it answers cuts off its whole upstream); walking forwards evaluates the rest. Nothing
//! allocates once the scratch exists.

use crate::graph::{Graph, NodeId, OutputId, Source};
use crate::nodes::{self, geometry, Ctx};
use crate::value::{Filtered, Footprint, ValueType};
use glam::{Mat2, Vec2};

/// Counters of the work that filtered evaluation did, for cost checks and profiles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Work {
    /// Perlin octaves evaluated (a fully filtered octave counts once, then ends its fractal).
    pub octaves: u64,
    /// Lattice corners / cells / feature-point searches visited by noise and patterns.
    pub lattice: u64,
}

impl Work {
    /// Adds another counter set.
    pub fn merge(&mut self, o: &Work) {
        self.octaves += o.octaves;
        self.lattice += o.lattice;
    }
}

/// A replacement of a node's filtered evaluation, e.g. by a cached tile lookup.
pub trait NodeOverride {
    /// The node's filtered value at `fp`, or `None` to evaluate it.
    fn lookup(&self, node: NodeId, fp: &Footprint) -> Option<Filtered>;

    /// Whether it never answers (then evaluation skips asking it node by node).
    fn never_answers(&self) -> bool {
        false
    }

    /// Whether [`lookup`](Self::lookup) would answer `node` at `fp`, decided without looking
    /// it up. Must not say `true` where `lookup` gives `None`. An evaluation whose outputs all
    /// come from answered nodes asks for those alone, without visiting the rest of the graph
    /// ([`Graph::eval`]); the default, `false`, always visits it.
    fn answers(&self, _node: NodeId, _fp: &Footprint) -> bool {
        false
    }
}

/// The override that never answers: plain evaluation.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoOverride;

impl NodeOverride for NoOverride {
    #[inline]
    fn lookup(&self, _: NodeId, _: &Footprint) -> Option<Filtered> {
        None
    }

    fn never_answers(&self) -> bool {
        true
    }
}

/// The nodes a set of outputs needs, in topological order.
#[derive(Clone, Debug)]
pub struct EvalOrder {
    nodes: Vec<NodeId>,
    outputs: Vec<OutputId>,
    /// The nodes the outputs read, each once, last first: the order the general path asks a
    /// [`NodeOverride`] for them when it answers them all.
    output_nodes: Vec<NodeId>,
}

impl EvalOrder {
    /// The nodes, in topological order.
    pub fn nodes(&self) -> &[NodeId] {
        &self.nodes
    }

    /// The outputs, in the order their values are written.
    pub fn outputs(&self) -> &[OutputId] {
        &self.outputs
    }
}

/// Per-thread evaluation memory and statistics. Create one per thread per graph; merge the
/// statistics of several with [`EvalScratch::merge_stats_into`].
#[derive(Debug)]
pub struct EvalScratch {
    values: Vec<Filtered>,
    needed: Vec<bool>,
    order: Vec<NodeId>,
    /// Evaluations, lookups, sampled timings, non-finite origins and work since creation or the
    /// last reset: the same record that merged statistics are.
    stats: EvalStats,
    /// Profiling: sampled timings per (node, bin), `bins` per node; empty when off.
    binned: BinnedTimings,
    /// Per-node counting and sampled timing on (the default); off only to measure their cost.
    instrumented: bool,
    /// The origin of the most recent evaluation that went non-finite, until taken.
    latest_nonfinite: Option<NonFinite>,
    /// Input slots of the node being evaluated ([`nodes::MAX_INPUTS`] of them).
    ins: Vec<Filtered>,
    /// The nodes a several-node direct evaluation needs ([`Graph::eval_nodes_direct`]).
    union: Vec<NodeId>,
    /// The nodes `union` was gathered for: a tile fill asks for the same nodes at every texel.
    union_of: Vec<NodeId>,
}

/// Where a graph evaluation first produced a value that is not finite: the node whose inputs were
/// all finite but whose output was not (a bug in its filtering rule: every node is meant to be
/// total), and the footprint it was evaluated at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonFinite {
    /// The node.
    pub node: NodeId,
    /// The footprint's centre.
    pub uv: Vec2,
    /// The footprint's standard deviation along its major axis, in uv units (0 at a point).
    pub sigma: f32,
}

impl NonFinite {
    /// `node `NAME` (CATEGORY) at uv (u, v), footprint σ S uv` for messages.
    pub fn describe(&self, graph: &Graph) -> String {
        format!(
            "node `{}` ({}) at uv ({}, {}), footprint σ {:.3e} uv",
            graph.node_name(self.node),
            graph.node_category(self.node),
            self.uv.x,
            self.uv.y,
            self.sigma
        )
    }
}

/// Whether every used channel of `v` is finite (mean, gradient, variance).
#[inline]
pub fn is_finite(v: &Filtered) -> bool {
    // One sum per channel: any infinity or NaN makes it non-finite (an overflowing sum of finite
    // parts is checked part by part).
    v.ch[..v.n()].iter().all(|c| {
        (c.mean + c.grad.x + c.grad.y + c.var).is_finite()
            || (c.mean.is_finite() && c.grad.is_finite() && c.var.is_finite())
    })
}

/// The standard deviation of `cov` along its major axis.
fn major_sigma(cov: Mat2) -> f32 {
    let (a, b, d) = (cov.x_axis.x, cov.x_axis.y, cov.y_axis.y);
    let h = 0.5 * (a + d);
    let r = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    (h + r).max(0.0).sqrt()
}

/// Sampled self-time of each node split by a caller-chosen bin (a profiler labels each
/// evaluation with the footprint's level). Off (empty) unless enabled.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BinnedTimings {
    /// Bins per node.
    pub bins: usize,
    /// One evaluation in this many of each node is timed ([`TIMING_PERIOD`] unless binned
    /// timing set another).
    pub period: u64,
    /// The bin the next evaluations are charged to.
    pub current: usize,
    /// Nanoseconds of the timed evaluations, index `node * bins + bin`.
    pub ns: Vec<u64>,
    /// Number of timed evaluations, index `node * bins + bin`.
    pub count: Vec<u64>,
    /// The longest timed evaluation, index `node * bins + bin` (see [`BinnedTimings::mean_ns`]).
    pub max: Vec<u64>,
}

/// A timed evaluation this many times the mean of the others of its node and bin is not the
/// node's cost but something that happened to it: a one-time setup (a pattern's per-thread memo,
/// 1.7 ms, charged to one evaluation of a node that otherwise costs 2 µs), a preemption, an
/// interrupt. Within a bin a node's genuine costs were seen to spread over less than 10×.
pub const TIMING_OUTLIER: f64 = 32.0;

impl BinnedTimings {
    /// Adds another recorder's timings (of the same graph and bins; sizing on first use).
    pub fn merge(&mut self, o: &BinnedTimings) {
        if self.ns.is_empty() {
            *self = o.clone();
            return;
        }
        for (a, b) in self.ns.iter_mut().zip(&o.ns) {
            *a += b;
        }
        for (a, b) in self.count.iter_mut().zip(&o.count) {
            *a += b;
        }
        for (a, b) in self.max.iter_mut().zip(&o.max) {
            *a = (*a).max(*b);
        }
    }

    /// Node `node`'s mean timed nanoseconds in bin `bin` and the evaluations it averages, `None`
    /// if none was timed there. The longest evaluation is left out when it is more than
    /// [`TIMING_OUTLIER`] times the mean of the others: one such evaluation among a bin's few
    /// dozen raised the mean 30-fold and the profile's predicted render time 1.8-fold.
    pub fn mean_ns(&self, node: usize, bin: usize) -> Option<(f64, u64)> {
        let k = node * self.bins + bin;
        let (ns, count) = (*self.ns.get(k)?, *self.count.get(k)?);
        robust_mean(ns, count, self.max[k])
    }
}

/// The mean of `count` timings summing to `sum`, the longest of which is `max`, leaving that one
/// out when it is an outlier (more than [`TIMING_OUTLIER`] times the others' mean); with the
/// number of timings averaged. `None` if there are none.
pub fn robust_mean(sum: u64, count: u64, max: u64) -> Option<(f64, u64)> {
    if count == 0 {
        return None;
    }
    if count >= 2 {
        let rest = sum.saturating_sub(max) as f64 / (count - 1) as f64;
        if max as f64 > TIMING_OUTLIER * rest.max(1.0) {
            return Some((rest, count - 1));
        }
    }
    Some((sum as f64 / count as f64, count))
}

/// Nanoseconds of one timing as the evaluator takes it (two clock reads and a subtraction),
/// measured once per process over 4000 pairs (about 0.2 ms).
pub fn clock_pair_ns() -> f64 {
    static NS: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *NS.get_or_init(|| {
        let reps = 4_000;
        let t = std::time::Instant::now();
        let mut sink = 0u128;
        for _ in 0..reps {
            let a = std::time::Instant::now();
            sink += a.elapsed().as_nanos();
        }
        std::hint::black_box(sink);
        t.elapsed().as_secs_f64() * 1e9 / f64::from(reps)
    })
}

/// One evaluation in this many of each node is timed (two clock reads, ~50 ns, per 64
/// evaluations: well under 1 % of a node evaluation's cost).
pub const TIMING_PERIOD: u64 = 64;

/// Merged statistics of one or more scratches.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EvalStats {
    /// Per node: filtered evaluations.
    pub evaluations: Vec<u64>,
    /// Per node: values answered by the override.
    pub lookups: Vec<u64>,
    /// Per node: nanoseconds spent in the sampled (timed) evaluations.
    pub timed_ns: Vec<u64>,
    /// Per node: number of timed evaluations (one in [`TIMING_PERIOD`]).
    pub timed: Vec<u64>,
    /// Per node: evaluations in which it was the first node to give a non-finite value.
    pub nonfinite: Vec<u64>,
    /// Work counters.
    pub work: Work,
}

fn add_into(into: &mut Vec<u64>, from: &[u64]) {
    if into.len() < from.len() {
        into.resize(from.len(), 0);
    }
    for (a, b) in into.iter_mut().zip(from) {
        *a += b;
    }
}

impl EvalStats {
    /// Adds another set of statistics of the same graph (sizing on first use).
    pub fn merge(&mut self, o: &EvalStats) {
        add_into(&mut self.evaluations, &o.evaluations);
        add_into(&mut self.lookups, &o.lookups);
        add_into(&mut self.timed_ns, &o.timed_ns);
        add_into(&mut self.timed, &o.timed);
        add_into(&mut self.nonfinite, &o.nonfinite);
        self.work.merge(&o.work);
    }

    /// Adds per-graph statistics `from` to `into` graph by graph (growing `into` to as many
    /// graphs as `from` has).
    pub fn merge_all(into: &mut Vec<EvalStats>, from: &[EvalStats]) {
        into.resize(from.len().max(into.len()), EvalStats::default());
        for (a, b) in into.iter_mut().zip(from) {
            a.merge(b);
        }
    }

    /// Estimated seconds spent evaluating node `i`: its evaluations times the mean of its timed
    /// ones less the timing's own cost ([`clock_pair_ns`]; it was most of what a cheap node's
    /// timings read: 51 ns for a `multiply` that costs 6).
    pub fn estimated_seconds(&self, i: usize) -> f64 {
        match (self.timed.get(i), self.timed_ns.get(i), self.evaluations.get(i)) {
            (Some(&t), Some(&ns), Some(&e)) if t > 0 => {
                e as f64 * (ns as f64 / t as f64 - clock_pair_ns()).max(0.0) * 1e-9
            }
            _ => 0.0,
        }
    }
}

impl EvalScratch {
    /// Scratch for `graph`.
    pub fn new(graph: &Graph) -> EvalScratch {
        let n = graph.node_count();
        EvalScratch {
            values: vec![Filtered::zero(ValueType::Float); n],
            needed: vec![false; n],
            order: Vec::with_capacity(n),
            stats: EvalStats {
                evaluations: vec![0; n],
                lookups: vec![0; n],
                timed_ns: vec![0; n],
                timed: vec![0; n],
                nonfinite: vec![0; n],
                work: Work::default(),
            },
            binned: BinnedTimings { period: TIMING_PERIOD, ..BinnedTimings::default() },
            instrumented: true,
            latest_nonfinite: None,
            ins: vec![Filtered::zero(ValueType::Float); nodes::MAX_INPUTS],
            union: Vec::new(),
            union_of: Vec::new(),
        }
    }

    /// Turns per-node evaluation counts and sampled timings off (or back on). They are on by
    /// default and cheap enough to stay on (`cargo bench -p graph --bench demo_graphs` measures
    /// their cost side by side); off, [`EvalScratch::evaluations`] and the timings stay zero
    /// while lookups and work counters still count.
    pub fn set_instrumented(&mut self, on: bool) {
        self.instrumented = on;
    }

    /// Starts recording sampled timings per node and per bin (`bins` bins; see
    /// [`EvalScratch::set_bin`]).
    /// One evaluation in `period` of each node is then timed (instead of [`TIMING_PERIOD`]).
    pub fn enable_binned_timing(&mut self, bins: usize, period: u64) {
        let n = self.values.len();
        let period = period.max(1);
        self.binned = BinnedTimings {
            bins,
            period,
            current: 0,
            ns: vec![0; n * bins],
            count: vec![0; n * bins],
            max: vec![0; n * bins],
        };
    }

    /// Charges the next evaluations' sampled timings to `bin` (ignored unless enabled; clamped).
    #[inline]
    pub fn set_bin(&mut self, bin: usize) {
        self.binned.current = bin.min(self.binned.bins.saturating_sub(1));
    }

    /// When node `i`'s evaluation about to start is one of the sampled timings (one in
    /// `binned.period` of its evaluations, when counting is on), the clock now.
    #[inline]
    fn timing_start(&self, i: usize) -> Option<std::time::Instant> {
        (self.instrumented && self.stats.evaluations[i].is_multiple_of(self.binned.period))
            .then(std::time::Instant::now)
    }

    /// Charges node `i`'s evaluation begun at `start` (see [`EvalScratch::timing_start`]) to
    /// its timings and, when binned timing is on, to the current bin.
    #[inline]
    fn timing_end(&mut self, i: usize, start: Option<std::time::Instant>) {
        let Some(start) = start else { return };
        let ns = start.elapsed().as_nanos() as u64;
        self.stats.timed_ns[i] += ns;
        self.stats.timed[i] += 1;
        let b = &mut self.binned;
        if b.bins > 0 {
            let k = i * b.bins + b.current;
            b.ns[k] += ns;
            b.count[k] += 1;
            b.max[k] = b.max[k].max(ns);
        }
    }

    /// Counts node `i`'s evaluation begun at `start` and charges its timing, if it was timed.
    #[inline]
    fn counted(&mut self, i: usize, start: Option<std::time::Instant>) {
        self.timing_end(i, start);
        self.stats.evaluations[i] += self.instrumented as u64;
    }

    /// The per-bin timings recorded so far.
    pub fn binned_timings(&self) -> &BinnedTimings {
        &self.binned
    }

    /// Evaluations per node since creation or the last reset.
    pub fn evaluations(&self) -> &[u64] {
        &self.stats.evaluations
    }

    /// Override answers per node.
    pub fn lookups(&self) -> &[u64] {
        &self.stats.lookups
    }

    /// Work counters.
    pub fn work(&self) -> Work {
        self.stats.work
    }

    /// Per node: the evaluations in which it was the first node to give a non-finite value.
    pub fn nonfinite(&self) -> &[u64] {
        &self.stats.nonfinite
    }

    /// The origin of the most recent evaluation that went non-finite since the last call, if
    /// any (and forgets it).
    #[inline]
    pub fn take_nonfinite(&mut self) -> Option<NonFinite> {
        self.latest_nonfinite.take()
    }

    /// Zeroes the statistics.
    pub fn reset_stats(&mut self) {
        let st = &mut self.stats;
        for v in [&mut st.evaluations, &mut st.lookups, &mut st.timed_ns, &mut st.timed, &mut st.nonfinite] {
            v.fill(0);
        }
        st.work = Work::default();
        self.latest_nonfinite = None;
    }

    /// Adds this scratch's statistics to `stats` (sized on first use).
    pub fn merge_stats_into(&self, stats: &mut EvalStats) {
        stats.merge(&self.stats);
    }
}

impl Graph {
    /// The order in which evaluating `outputs` together visits the nodes.
    pub fn eval_order(&self, outputs: &[OutputId]) -> EvalOrder {
        let mut nodes: Vec<NodeId> = Vec::new();
        for o in outputs {
            if let Source::Node { node, .. } = self.output(*o).source {
                nodes.extend_from_slice(self.upstream(node));
            }
        }
        nodes.sort_unstable();
        nodes.dedup();
        let mut output_nodes: Vec<NodeId> = outputs
            .iter()
            .filter_map(|o| match self.output(*o).source {
                Source::Node { node, .. } => Some(node),
                _ => None,
            })
            .collect();
        output_nodes.sort_unstable_by(|a, b| b.cmp(a));
        output_nodes.dedup();
        EvalOrder { nodes, outputs: outputs.to_vec(), output_nodes }
    }

    /// Evaluates the order's outputs filtered over `fp`, writing them to `out` (one per output).
    pub fn eval(
        &self,
        order: &EvalOrder,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
        out: &mut [Filtered],
    ) {
        if !ov.never_answers() && self.eval_answered(order, fp, scratch, ov, out) {
            return;
        }
        for &n in &order.nodes {
            scratch.needed[n.0 as usize] = false;
        }
        for o in &order.outputs {
            if let Source::Node { node, .. } = self.output(*o).source {
                scratch.needed[node.0 as usize] = true;
            }
        }
        self.run(&order.nodes, &[], fp, scratch, ov);
        self.resolve_outputs(order, fp, scratch, out);
    }

    /// Reads the order's outputs from their nodes' values in `scratch` into `out`.
    fn resolve_outputs(&self, order: &EvalOrder, fp: &Footprint, scratch: &mut EvalScratch, out: &mut [Filtered]) {
        let ctx_point = is_point(fp);
        for (slot, o) in out.iter_mut().zip(&order.outputs) {
            *slot = self.resolve(&self.output(*o).source, fp, ctx_point, scratch);
            slot.ty = self.output(*o).ty;
        }
    }

    /// [`Self::eval`] where `ov` answers every node an output reads: each such node is looked
    /// up once and nothing else is visited (a render's wide footprints, whose cached outputs are
    /// all read from tiles, spent most of an evaluation skipping the graph's other nodes one
    /// unpredictable branch at a time). Returns false otherwise, having looked nothing up
    /// (unless the override broke its word: said it answers a node, then gave `None`; the
    /// general path then asks again).
    fn eval_answered(
        &self,
        order: &EvalOrder,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
        out: &mut [Filtered],
    ) -> bool {
        // Tiles are filled in the order the general path asks for them, so co-filling and the
        // cache's counts are what they were.
        if !order.output_nodes.iter().all(|&node| ov.answers(node, fp)) {
            return false;
        }
        for &node in &order.output_nodes {
            let i = node.0 as usize;
            match ov.lookup(node, fp) {
                Some(v) => scratch.values[i] = v,
                None => {
                    // An override that broke its word: the general path asks again.
                    debug_assert!(false, "a node override said it answers node {i} but gave no value");
                    return false;
                }
            }
            scratch.stats.lookups[i] += 1;
        }
        self.resolve_outputs(order, fp, scratch, out);
        true
    }

    /// Evaluates one output filtered over `fp`.
    pub fn eval_output(&self, output: OutputId, fp: &Footprint, scratch: &mut EvalScratch) -> Filtered {
        self.eval_output_with(output, fp, scratch, &NoOverride)
    }

    /// Evaluates one output filtered over `fp`, asking `ov` for node values first.
    pub fn eval_output_with(
        &self,
        output: OutputId,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
    ) -> Filtered {
        let o = self.output(output);
        if let Source::Node { node, .. } = o.source {
            let upstream = self.upstream(node);
            for &n in upstream {
                scratch.needed[n.0 as usize] = false;
            }
            scratch.needed[node.0 as usize] = true;
            self.run(upstream, &[], fp, scratch, ov);
        }
        let mut v = self.resolve(&o.source, fp, is_point(fp), scratch);
        v.ty = o.ty;
        v
    }

    /// Evaluates `node` itself filtered over `fp` (never replaced by `ov`), its inputs through
    /// `ov`. A tile fill calls this at texel centres with a one-texel footprint.
    pub fn eval_node_direct(
        &self,
        node: NodeId,
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
    ) -> Filtered {
        let upstream = self.upstream(node);
        for &n in upstream {
            scratch.needed[n.0 as usize] = false;
        }
        scratch.needed[node.0 as usize] = true;
        self.run(upstream, &[node], fp, scratch, ov);
        scratch.values[node.0 as usize]
    }

    /// [`Self::eval_node_direct`] for several nodes in one pass over the union of what they need
    /// (none of them replaced by `ov`), writing their values to `out` in order. Each value is the
    /// one [`Self::eval_node_direct`] gives for its node alone, bit for bit, as long as no node of
    /// `nodes` is upstream of another (that one would be evaluated here instead of asked of
    /// `ov`): a node's value depends on its inputs' values only. (At a point footprint where a
    /// node that reads gradients is among those needed, the nodes are evaluated one by one.)
    /// Tile fills of nodes that the same requests read compute their shared upstream once this
    /// way.
    pub fn eval_nodes_direct(
        &self,
        nodes: &[NodeId],
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
        out: &mut [Filtered],
    ) {
        let mut union = std::mem::take(&mut scratch.union);
        // (Empty: taken by an evaluation that panicked and never put it back.)
        if union.is_empty() || scratch.union_of != nodes {
            union.clear();
            for &n in nodes {
                union.extend_from_slice(self.upstream(n));
            }
            // Ascending ids are a topological order.
            union.sort_unstable();
            union.dedup();
            scratch.union_of.clear();
            scratch.union_of.extend_from_slice(nodes);
        }
        // At a point, a node that reads its inputs' gradients makes the whole pass keep them
        // (see `run`): the others' gradients would then depend on what else was evaluated.
        if is_point(fp) && union.iter().any(|id| self.nodes[id.0 as usize].reads_gradients) {
            scratch.union = union;
            for (o, &n) in out.iter_mut().zip(nodes) {
                *o = self.eval_node_direct(n, fp, scratch, ov);
            }
            return;
        }
        for &n in &union {
            scratch.needed[n.0 as usize] = false;
        }
        for &n in nodes {
            scratch.needed[n.0 as usize] = true;
        }
        self.run(&union, nodes, fp, scratch, ov);
        for (o, n) in out.iter_mut().zip(nodes) {
            *o = scratch.values[n.0 as usize];
        }
        scratch.union = union;
    }

    /// Evaluates what `nodes` (in topological order, each upstream of what was asked for) the
    /// request needs, asking `ov` first for every node but those of `direct`.
    fn run(
        &self,
        nodes: &[NodeId],
        direct: &[NodeId],
        fp: &Footprint,
        scratch: &mut EvalScratch,
        ov: &dyn NodeOverride,
    ) {
        scratch.order.clear();
        if ov.never_answers() {
            // Every node of `nodes` is upstream of what was asked for, so all are needed.
            scratch.order.extend(nodes.iter().rev());
        } else {
            for &id in nodes.iter().rev() {
                let i = id.0 as usize;
                if !scratch.needed[i] {
                    continue;
                }
                if !direct.contains(&id) {
                    if let Some(v) = ov.lookup(id, fp) {
                        scratch.values[i] = v;
                        scratch.stats.lookups[i] += 1;
                        continue;
                    }
                }
                scratch.order.push(id);
                for s in &self.nodes[i].inputs {
                    if let Source::Node { node, .. } = s {
                        scratch.needed[node.0 as usize] = true;
                    }
                }
            }
        }
        // Nodes that read their inputs' gradients (heighttonormal) need them at points too.
        let point = is_point(fp) && !scratch.order.iter().any(|id| self.nodes[id.0 as usize].reads_gradients);
        // The input slots live in the scratch: zeroing 24 of them per evaluation cost as much as
        // a cheap node.
        let mut ins = std::mem::take(&mut scratch.ins);
        if ins.len() < nodes::MAX_INPUTS {
            // Only after an evaluation that panicked and never put them back.
            ins = vec![Filtered::zero(ValueType::Float); nodes::MAX_INPUTS];
        }
        // The texture coordinate, once per evaluation (inputs copy it, and the nodes' constant
        // inputs, from values built beforehand: a value assembled field by field and copied
        // whole at once stalls the copy).
        let tc = geometry::texcoord(&Ctx { fp, point, work: &mut Work::default() });
        self.forward(fp, point, &tc, &mut ins, scratch, false);
        // Values are checked once all are done (checking each right after its node wrote it
        // stalls on the fresh stores). Only if one is not finite is the evaluation run again, one
        // node at a time with the rule every node shares: overflow saturates, the first NaN
        // names its node. The result is the same as checking each node as it goes.
        if scratch.order.iter().any(|id| !is_finite(&scratch.values[id.0 as usize])) {
            self.forward(fp, point, &tc, &mut ins, scratch, true);
        }
        scratch.ins = ins;
    }

    /// Evaluates `scratch.order` (last to first). `careful`: saturate each node's overflow and
    /// record the first NaN's origin, without counting the evaluations again.
    fn forward(
        &self,
        fp: &Footprint,
        point: bool,
        tc: &Filtered,
        ins: &mut [Filtered],
        scratch: &mut EvalScratch,
        careful: bool,
    ) {
        let mut poisoned = false;
        let mut spare = Work::default();
        for k in (0..scratch.order.len()).rev() {
            let id = scratch.order[k];
            let node = &self.nodes[id.0 as usize];
            if let (Some(op), false) = (node.direct, careful) {
                // Inputs read where they lie: upstream values (earlier ids: the order is
                // topological), the node's constants, the texture coordinate.
                let i = id.0 as usize;
                let start = scratch.timing_start(i);
                let (done, rest) = scratch.values.split_at_mut(i);
                let mut refs: [&Filtered; 8] = [tc; 8];
                for ((r, s), c) in refs.iter_mut().zip(&node.inputs).zip(node.consts.iter()) {
                    *r = match s {
                        Source::Node { node, .. } => &done[node.0 as usize],
                        Source::Constant(_) => c,
                        _ => tc,
                    };
                }
                let out = &mut rest[0];
                nodes::math::eval_channels(op, node.ty, &refs[..node.inputs.len()], fp, out);
                if point {
                    nodes::point_gradients(out);
                }
                scratch.counted(i, start);
                continue;
            }
            // Each arm copies straight into the slot: a value assembled in a temporary and copied
            // from there is read back across the temporary's fresh stores (a stall per input).
            for ((slot, s), c) in ins.iter_mut().zip(&node.inputs).zip(node.consts.iter()) {
                match s {
                    Source::Constant(_) => *slot = *c,
                    Source::Texcoord => *slot = *tc,
                    Source::Node { node, channel: None } => *slot = scratch.values[node.0 as usize],
                    _ => *slot = self.resolve(s, fp, point, scratch),
                }
            }
            let n_in = node.inputs.len();
            let i = id.0 as usize;
            if careful {
                let mut ctx = Ctx { fp, point, work: &mut spare };
                let mut v = nodes::eval(&node.op, node.ty, &ins[..n_in], &mut ctx);
                if !is_finite(&v) {
                    // Overflow saturates; what is still not finite is a NaN. The first of this
                    // evaluation names its node as the origin (every input was finite);
                    // downstream nodes carry it on and are not counted.
                    nodes::saturate(&mut v);
                    if !poisoned && !is_finite(&v) {
                        poisoned = true;
                        scratch.stats.nonfinite[i] += 1;
                        scratch.latest_nonfinite = Some(NonFinite { node: id, uv: fp.uv, sigma: major_sigma(fp.cov) });
                    }
                }
                scratch.values[i] = v;
                continue;
            }
            let start = scratch.timing_start(i);
            let mut ctx = Ctx { fp, point, work: &mut scratch.stats.work };
            nodes::eval_into(&node.op, node.ty, &ins[..n_in], &mut ctx, &mut scratch.values[i]);
            scratch.counted(i, start);
        }
    }

    fn resolve(&self, s: &Source, fp: &Footprint, point: bool, scratch: &mut EvalScratch) -> Filtered {
        match s {
            Source::Constant(v) => Filtered::constant(*v),
            Source::Texcoord => {
                let mut w = Work::default();
                geometry::texcoord(&Ctx { fp, point, work: &mut w })
            }
            Source::Geometry(g) => {
                let mut w = Work::default();
                geometry::geomprop(*g, &Ctx { fp, point, work: &mut w })
            }
            Source::Node { node, channel } => {
                let v = scratch.values[node.0 as usize];
                match channel {
                    None => v,
                    Some(c) => {
                        let mut f = Filtered::zero(ValueType::Float);
                        f.ch[0] = v.ch[*c as usize];
                        f
                    }
                }
            }
        }
    }
}

#[inline]
fn is_point(fp: &Footprint) -> bool {
    fp.cov == Mat2::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sum, count and max of `t`, as a recorder keeps them.
    fn record(t: &[u64]) -> (u64, u64, u64) {
        (t.iter().sum(), t.len() as u64, t.iter().copied().max().unwrap_or(0))
    }

    #[test]
    fn robust_mean_leaves_out_one_setup_cost_and_nothing_else() {
        // 40 evaluations of about 2 µs and one that built a 1.7 ms memo.
        let mut t: Vec<u64> = (0..40).map(|k| 1800 + 10 * k).collect();
        let plain = t.iter().sum::<u64>() as f64 / t.len() as f64;
        t.push(1_700_000);
        let (sum, count, max) = record(&t);
        let (mean, n) = robust_mean(sum, count, max).unwrap();
        assert_eq!(n, 40);
        assert!((mean - plain).abs() < 1e-9, "{mean} {plain}");
        // A genuine spread (a node whose cost grows 20-fold within a bin) is kept whole.
        let t: Vec<u64> = (0..30).map(|k| 100 + 70 * k).chain([2000, 2100]).collect();
        let (sum, count, max) = record(&t);
        assert_eq!(robust_mean(sum, count, max), Some((sum as f64 / count as f64, count)));
        // One timing cannot be judged; none gives nothing.
        assert_eq!(robust_mean(5_000_000, 1, 5_000_000), Some((5e6, 1)));
        assert_eq!(robust_mean(0, 0, 0), None);
    }

    #[test]
    fn estimated_seconds_leave_out_the_clocks_cost() {
        let clock = clock_pair_ns();
        assert!(clock.is_finite() && clock > 0.0 && clock < 1e6, "{clock}");
        // 1000 evaluations, 10 timed: at 2 µs plus the clock each, and at a tenth of the clock.
        let stats = |mean: f64| EvalStats {
            evaluations: vec![1000],
            timed: vec![10],
            timed_ns: vec![(10.0 * mean).round() as u64],
            ..EvalStats::default()
        };
        let s = stats(2000.0 + clock).estimated_seconds(0);
        assert!((s - 2e-6 * 1000.0).abs() < 1e-7, "{s}"); // timed_ns is whole nanoseconds
        assert_eq!(stats(0.1 * clock).estimated_seconds(0), 0.0);
    }

    #[test]
    fn merged_bins_keep_each_bins_longest_timing() {
        let mut a =
            BinnedTimings { bins: 2, period: 1, current: 0, ns: vec![10, 20], count: vec![1, 2], max: vec![10, 15] };
        let b =
            BinnedTimings { bins: 2, period: 1, current: 1, ns: vec![5000, 5], count: vec![3, 1], max: vec![4900, 5] };
        a.merge(&b);
        assert_eq!((a.ns.clone(), a.count.clone(), a.max.clone()), (vec![5010, 25], vec![4, 3], vec![4900, 15]));
        // Bin 0: 4900 is more than 32× the others' mean (110 / 3): left out. Bin 1: 15 is not.
        assert_eq!(a.mean_ns(0, 0), Some((110.0 / 3.0, 3)));
        assert_eq!(a.mean_ns(0, 1), Some((25.0 / 3.0, 3)));
        let mut empty = BinnedTimings::default();
        empty.merge(&a);
        assert_eq!(empty, a);
    }
}
