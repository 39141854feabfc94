//! The identity measures (Ristani et al., 2016) with py-motmetrics' definitions: IDF1, IDP, IDR.
//!
//! Each true trajectory is assigned at most one hypothesis trajectory and each hypothesis at most
//! one true trajectory, once for the whole sequence, so that the frames in which an assigned pair
//! is within the gate (the identity true positives, IDTP) are as many as possible. Then
//! IDFN = true objects − IDTP, IDFP = hypotheses − IDTP, IDP = IDTP / (IDTP + IDFP),
//! IDR = IDTP / (IDTP + IDFN) and IDF1 = 2 IDTP / (true objects + hypotheses).
//!
//! py-motmetrics states this as a minimum-cost assignment of IDFP + IDFN over an augmented
//! matrix; the cost of an assignment is the total count of both sides minus twice its IDTP, so
//! maximising IDTP is the same problem, solved here on the sparse graph of pairs that were ever
//! within the gate.

use std::collections::HashMap;

use serde::Serialize;

use crate::assign::{self, Edge};
use crate::ratio::serialize_ratio;
use crate::sequence::{Frame, Pair};

/// The identity measures of a sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identity {
    pub idtp: usize,
    pub idfp: usize,
    pub idfn: usize,
    #[serde(serialize_with = "serialize_ratio")]
    pub idf1: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub idp: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub idr: f64,
}

/// One pair of the global identity assignment: a true trajectory, the hypothesis trajectory
/// assigned to it, and the frames in which the two are within the gate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Assigned {
    pub truth: u32,
    pub hypothesis: u32,
    pub frames: usize,
}

/// Counts per id and per pair within the gate, fed one frame at a time.
#[derive(Debug, Clone, Default)]
pub(crate) struct IdentityCounts {
    truth: usize,
    hypotheses: usize,
    truth_ids: usize,
    hypothesis_ids: usize,
    together: HashMap<(u32, u32), usize>,
}

impl IdentityCounts {
    pub(crate) fn new(truth_ids: usize, hypothesis_ids: usize) -> IdentityCounts {
        IdentityCounts { truth_ids, hypothesis_ids, ..IdentityCounts::default() }
    }

    pub(crate) fn frame(&mut self, frame: &Frame, gated: &[Pair]) {
        self.truth += frame.truth.len();
        self.hypotheses += frame.hypotheses.len();
        for p in gated {
            let key = (frame.truth[p.truth].id, frame.hypotheses[p.hypothesis].id);
            *self.together.entry(key).or_default() += 1;
        }
    }

    /// The measures and the assignment behind them (ordered by true id).
    pub(crate) fn finish(&self) -> (Identity, Vec<Assigned>) {
        let mut keys: Vec<(u32, u32)> = self.together.keys().copied().collect();
        keys.sort_unstable();
        let edges: Vec<Edge> = keys
            .iter()
            .map(|&(t, h)| Edge { row: t as usize, col: h as usize, value: self.together[&(t, h)] as f64 })
            .collect();
        let assigned: Vec<Assigned> = assign::max_weight(self.truth_ids, self.hypothesis_ids, &edges)
            .into_iter()
            .map(|(t, h)| {
                let key = (t as u32, h as u32);
                Assigned { truth: key.0, hypothesis: key.1, frames: self.together[&key] }
            })
            .collect();
        let idtp: usize = assigned.iter().map(|a| a.frames).sum();
        let idfn = self.truth - idtp;
        let idfp = self.hypotheses - idtp;
        let identity = Identity {
            idtp,
            idfp,
            idfn,
            idf1: 2.0 * idtp as f64 / (self.truth + self.hypotheses) as f64,
            idp: idtp as f64 / (idtp + idfp) as f64,
            idr: idtp as f64 / (idtp + idfn) as f64,
        };
        (identity, assigned)
    }
}
