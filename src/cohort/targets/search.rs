//! The bounded candidate search of a targeted shape. It is engine-agnostic: the cohort
//! generator implements [`CandidateSource`] around the engine, tests with cheap stand-ins.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::Targets;
use crate::anatomy::shape::ShapeAnatomy;

/// Training shapes that guided candidates mix: those meeting every target, or, when fewer
/// than `arity` do, the `arity` nearest to meeting them (ties by index).
pub fn guided_pool(
    targets: &Targets,
    training: &[Option<ShapeAnatomy>],
    arity: usize,
) -> Vec<usize> {
    let mut ranked: Vec<(f64, usize)> = training
        .iter()
        .enumerate()
        .map(|(i, a)| (targets.miss(a.as_ref()), i))
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let inside = ranked.iter().filter(|(miss, _)| *miss == 0.0).count();
    ranked.truncate(inside.max(arity).min(training.len()));
    ranked.into_iter().map(|(_, i)| i).collect()
}

/// Whether candidate `attempt` is guided: the first is the plain draw (so a shape that meets
/// its targets at once equals the unconditioned shape), then plain and guided draws
/// alternate, keeping some of the plain draws' diversity.
pub fn is_guided(attempt: u32) -> bool {
    attempt % 2 == 1
}

/// `arity` distinct training indices from `pool`, drawn from `seed`.
pub fn guided_indices(seed: u64, pool: &[usize], arity: usize) -> Vec<usize> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7461_7267_6574);
    let mut pool = pool.to_vec();
    let k = arity.min(pool.len());
    for i in 0..k {
        let j = rng.random_range(i..pool.len());
        pool.swap(i, j);
    }
    pool.truncate(k);
    pool
}

/// A candidate meshed at the final resolution and measured.
#[derive(Debug, Clone)]
pub struct Measured<C> {
    /// What the caller keeps (mesh, mixture, …).
    pub candidate: C,
    /// Its measurements at the final resolution, or why they failed.
    pub anatomy: Result<ShapeAnatomy, String>,
    /// The caller's other constraints hold (e.g. the minimum novelty).
    pub accept: bool,
    /// Tie-breaker among candidates missing equally (larger is better, e.g. novelty).
    pub rank: f64,
}

/// The kept candidate of a search.
#[derive(Debug, Clone)]
pub struct SearchOutcome<C> {
    /// The kept candidate.
    pub kept: Measured<C>,
    /// Its attempt number.
    pub attempt: u32,
    /// Candidates drawn and measured (coarse or final), at least 1.
    pub candidates: u32,
    /// How many of them were weight refinements of the one before ([`super::refine::refine_weights`]).
    pub refined: u32,
    /// Whether the kept candidate meets every target (at the final resolution).
    pub met: bool,
}

/// Weight refinements in a row from one drawn mixture before the search draws afresh.
pub const MAX_REFINEMENTS: u32 = 3;

/// What a search draws, meshes and measures: the service and the command line each
/// implement it around their engine, tests with a cheap stand-in.
pub trait CandidateSource {
    /// A candidate's mixture (what gets meshed).
    type Spec;
    /// What the caller keeps of a finished candidate.
    type Kept;
    /// Why drawing or meshing failed (ends the search).
    type Error;
    /// The drawn mixture of candidate `attempt` (deterministic in the attempt number).
    fn draw(&mut self, attempt: u32) -> Result<Self::Spec, Self::Error>;
    /// A mixture with the same parts as `spec` whose weights should bring `measured`
    /// (what `spec` gave) into the targets, or `None` when its weights may not change.
    fn refine(&mut self, spec: &Self::Spec, measured: &ShapeAnatomy) -> Option<Self::Spec>;
    /// Meshes `spec` coarsely and measures it.
    fn screen(&mut self, spec: &Self::Spec) -> Result<Result<ShapeAnatomy, String>, Self::Error>;
    /// Meshes `spec` at the final resolution and measures it.
    fn finalize(
        &mut self,
        attempt: u32,
        spec: &Self::Spec,
    ) -> Result<Measured<Self::Kept>, Self::Error>;
}

/// Searches at most `max_candidates` candidates for one that meets `targets` and the
/// caller's other constraints. With `screening`, each candidate is first measured on a
/// coarse mesh and only candidates that pass are meshed at the final resolution and
/// measured again. A candidate that misses is followed by a refinement of its weights
/// (up to [`MAX_REFINEMENTS`] in a row while the miss shrinks), otherwise by a fresh draw.
/// The first candidate that passes every check is kept; otherwise the final candidate
/// missing least (then accepted, then highest rank), or, when none passed the screen, the
/// best screened one meshed at the final resolution.
pub fn search<S: CandidateSource>(
    targets: &Targets,
    max_candidates: u32,
    screening: bool,
    source: &mut S,
) -> Result<SearchOutcome<S::Kept>, S::Error> {
    let mut best_final: Option<(u32, f64, Measured<S::Kept>)> = None;
    let mut best_screen: Option<(u32, f64, S::Spec)> = None;
    let (mut candidates, mut refined) = (0, 0);
    // The refinement to try next, its place in the chain and the miss it must beat.
    let mut next: Option<(S::Spec, u32, f64)> = None;
    for attempt in 0..max_candidates.max(1) {
        candidates += 1;
        let (spec, chain, previous_miss) = match next.take() {
            Some(n) => {
                refined += 1;
                n
            }
            None => (source.draw(attempt)?, 0, f64::INFINITY),
        };
        let (miss, anatomy) = if screening {
            let anatomy = source.screen(&spec)?.ok();
            (targets.miss(anatomy.as_ref()), anatomy)
        } else {
            (0.0, None)
        };
        let (miss, anatomy) = if miss > 0.0 {
            (miss, anatomy)
        } else {
            let measured = source.finalize(attempt, &spec)?;
            let miss = targets.miss(measured.anatomy.as_ref().ok());
            let anatomy = measured.anatomy.clone().ok();
            let done = miss == 0.0 && measured.accept;
            let better = best_final
                .as_ref()
                .is_none_or(|(_, best_miss, best)| better(miss, &measured, *best_miss, best));
            if better {
                best_final = Some((attempt, miss, measured));
            }
            if done {
                break;
            }
            (miss, anatomy)
        };
        if chain < MAX_REFINEMENTS && miss > 0.0 && miss.is_finite() && miss < previous_miss {
            next = anatomy
                .and_then(|a| source.refine(&spec, &a))
                .map(|s| (s, chain + 1, miss));
        }
        if miss > 0.0 && best_screen.as_ref().is_none_or(|(_, best, _)| miss < *best) {
            best_screen = Some((attempt, miss, spec));
        }
    }
    let (attempt, miss, kept) = match best_final {
        Some(best) => best,
        None => {
            let (attempt, _, spec) = best_screen.expect("at least one candidate was screened");
            let measured = source.finalize(attempt, &spec)?;
            (
                attempt,
                targets.miss(measured.anatomy.as_ref().ok()),
                measured,
            )
        }
    };
    Ok(SearchOutcome {
        kept,
        attempt,
        candidates,
        refined,
        met: miss == 0.0,
    })
}

fn better<C>(miss: f64, m: &Measured<C>, best_miss: f64, best: &Measured<C>) -> bool {
    if miss != best_miss {
        return miss < best_miss;
    }
    if m.accept != best.accept {
        return m.accept;
    }
    m.rank > best.rank
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{anatomy, targets};
    use super::*;

    #[test]
    fn the_guided_pool_holds_the_shapes_inside_or_the_nearest() {
        let training: Vec<_> = [18.0, 24.0, 26.0, 31.0, 25.0, 40.0]
            .into_iter()
            .map(|a| Some(anatomy(Some(a), 60.0)))
            .collect();
        let t = targets(&[("annulus_mm", Some(23.0), Some(27.0))]).unwrap();
        let mut pool = guided_pool(&t, &training, 2);
        pool.sort_unstable();
        assert_eq!(pool, [1, 2, 4]);
        // Four needed: the three inside and the nearest outside (31 misses by 4, 18 by 5).
        let mut pool = guided_pool(&t, &training, 4);
        pool.sort_unstable();
        assert_eq!(pool, [1, 2, 3, 4]);
        let picked = guided_indices(9, &pool, 3);
        assert_eq!(picked, guided_indices(9, &pool, 3));
        let mut distinct = picked.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 3);
        assert!(picked.iter().all(|i| pool.contains(i)));
    }

    /// A stand-in for draw + mesh + measure: candidate `a` has annulus `values[a]`; the
    /// coarse measurement reads 0.5 mm low. Specs are attempt numbers and never refined.
    struct Table<'a> {
        values: &'a [f64],
        accept: bool,
        ranks: &'a [f64],
        screened: Vec<u32>,
        finals: Vec<u32>,
    }

    impl<'a> Table<'a> {
        fn new(values: &'a [f64]) -> Self {
            Self {
                values,
                accept: true,
                ranks: &[],
                screened: Vec::new(),
                finals: Vec::new(),
            }
        }
    }

    impl CandidateSource for Table<'_> {
        type Spec = u32;
        type Kept = u32;
        type Error = ();
        fn draw(&mut self, attempt: u32) -> Result<u32, ()> {
            Ok(attempt)
        }
        fn refine(&mut self, _: &u32, _: &ShapeAnatomy) -> Option<u32> {
            None
        }
        fn screen(&mut self, &a: &u32) -> Result<Result<ShapeAnatomy, String>, ()> {
            self.screened.push(a);
            Ok(Ok(anatomy(Some(self.values[a as usize] - 0.5), 60.0)))
        }
        fn finalize(&mut self, attempt: u32, &a: &u32) -> Result<Measured<u32>, ()> {
            assert_eq!(attempt, a);
            self.finals.push(a);
            Ok(Measured {
                candidate: a,
                anatomy: Ok(anatomy(self.values.get(a as usize).copied(), 60.0)),
                accept: self.accept,
                rank: self.ranks.get(a as usize).copied().unwrap_or(0.0),
            })
        }
    }

    fn run(
        values: &[f64],
        max: u32,
        screening: bool,
        target: (f64, f64),
    ) -> (SearchOutcome<u32>, Vec<u32>, Vec<u32>) {
        let t = targets(&[("annulus_mm", Some(target.0), Some(target.1))]).unwrap();
        let mut table = Table::new(values);
        let outcome = search(&t, max, screening, &mut table).unwrap();
        (outcome, table.screened, table.finals)
    }

    #[test]
    fn the_search_stops_at_the_first_candidate_that_passes_both_checks() {
        let values = [30.0, 21.0, 25.0, 24.0, 26.0];
        let (o, screened, finals) = run(&values, 5, true, (23.0, 27.0));
        assert_eq!(
            (o.attempt, o.candidates, o.met, o.kept.candidate),
            (2, 3, true, 2)
        );
        assert_eq!((screened, finals), (vec![0, 1, 2], vec![2]));
        // Without screening every candidate is meshed at the final resolution.
        let (o, screened, finals) = run(&values, 5, false, (23.0, 27.0));
        assert_eq!((o.attempt, o.candidates, o.met), (2, 3, true));
        assert_eq!((screened.len(), finals), (0, vec![0, 1, 2]));
    }

    #[test]
    fn a_coarse_pass_that_fails_the_final_check_keeps_searching() {
        // Candidate 0 reads 27.0 coarse (inside) but 27.5 final (outside).
        let values = [27.5, 30.0, 24.0];
        let (o, _, finals) = run(&values, 5, true, (23.0, 27.0));
        assert_eq!(finals, [0, 2]);
        assert_eq!((o.attempt, o.candidates, o.met), (2, 3, true));
    }

    #[test]
    fn an_unmet_search_is_bounded_and_keeps_the_closest_candidate() {
        let values = [30.0, 28.0, 35.0, 29.0];
        let (o, screened, finals) = run(&values, 4, true, (23.0, 27.0));
        assert_eq!(screened, [0, 1, 2, 3]);
        // None passed the screen: the closest screened one is meshed once at the end.
        assert_eq!(finals, [1]);
        assert_eq!((o.attempt, o.candidates, o.met), (1, 4, false));
        let (o, _, finals) = run(&values, 4, false, (23.0, 27.0));
        assert_eq!(
            (finals.len(), o.attempt, o.candidates, o.met),
            (4, 1, 4, false)
        );
    }

    #[test]
    fn other_constraints_and_rank_break_ties() {
        let t = targets(&[("length_mm", Some(50.0), None)]).unwrap();
        let mut table = Table {
            accept: false,
            ranks: &[1.0, 3.0, 2.0, 0.0],
            ..Table::new(&[])
        };
        let o = search(&t, 4, false, &mut table).unwrap();
        // Every candidate meets the target but none is accepted: all four are tried and
        // the highest rank is kept; the targets themselves are met.
        assert_eq!(
            (o.candidates, o.attempt, o.met, o.kept.accept),
            (4, 1, true, false)
        );
        assert!(table.screened.is_empty());
    }
}
