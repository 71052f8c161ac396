//! Alpha-beta swap moves of [`CrfSolver`].

use super::problem::{Checked, Energy};
use super::problem::{Cost, CrfProblem, Labelling, MoveConfig};
use super::solver::CrfSolver;
use crate::error::Result;

// Node and label indices address several parallel arrays at once in these loops.
#[allow(clippy::needless_range_loop)]
impl<C: Cost> CrfSolver<C> {
    /// Alpha-beta swap: for each pair of labels (α, β), the nodes labelled α or β may
    /// exchange them in one min-cut move; repeats until a cycle brings no improvement.
    pub fn alpha_beta_swap(
        &mut self,
        problem: &CrfProblem<C>,
        init: Option<&[i32]>,
        config: &MoveConfig,
    ) -> Result<Labelling<C>> {
        let c = self.check(problem, false)?;
        let mut labels = c.check_init(init)?;
        let mut e = c.energy(&labels);
        let mut trace = vec![e.value()];
        let l = c.l;
        let mut version = 0usize;
        let mut failed_at = vec![usize::MAX; l * l];
        let mut count = vec![0usize; l];
        let (mut cycles, mut tried) = (0, 0);
        while cycles < config.max_cycles {
            cycles += 1;
            let mut improved = false;
            for alpha in 0..l {
                for beta in alpha + 1..l {
                    count.fill(0);
                    for &x in &labels {
                        count[x as usize] += 1;
                    }
                    let useless = count[alpha] + count[beta] == 0
                        || !c.allowed_somewhere[alpha] && count[alpha] == 0
                        || !c.allowed_somewhere[beta] && count[beta] == 0;
                    if useless || failed_at[alpha * l + beta] == version {
                        continue;
                    }
                    tried += 1;
                    let new_e = self.swap_move(&c, &labels, alpha as i32, beta as i32);
                    if new_e.lt(&e) {
                        std::mem::swap(&mut labels, &mut self.candidate);
                        e = new_e;
                        trace.push(e.value());
                        version += 1;
                        improved = true;
                    } else {
                        failed_at[alpha * l + beta] = version;
                    }
                }
            }
            if !improved {
                break;
            }
        }
        Ok(Labelling {
            labels,
            energy: e.value(),
            trace,
            cycles,
            moves_tried: tried,
        })
    }

    /// Builds and solves the swap move of (α, β): x = 0 gives α, x = 1 gives β.
    fn swap_move(&mut self, c: &Checked<C>, labels: &[i32], alpha: i32, beta: i32) -> Energy<C> {
        let (a, b) = (alpha as usize, beta as usize);
        let in_set = |x: i32| x == alpha || x == beta;
        self.graph.reset();
        // Swap moves set capacities anywhere: the next expansion move clears it all.
        self.touched_valid = false;
        for i in 0..c.n {
            if in_set(labels[i]) {
                self.e0[i] = c.u_graph(i, a);
                self.e1[i] = c.u_graph(i, b);
            }
        }
        for (k, &[i, j]) in c.edges.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let (fi, fj) = (labels[i], labels[j]);
            if i == j {
                continue;
            }
            match (in_set(fi), in_set(fj)) {
                (true, true) => {
                    let eb = c.pair(k, alpha, beta);
                    let ec = c.pair(k, beta, alpha);
                    // A = D = 0: unary parts C·x_i and C(1 − x_j), arc B + C.
                    self.e1[i] += ec;
                    self.e0[j] += ec;
                    self.graph.set_edge_caps_unchecked(k, eb + ec, C::ZERO);
                }
                (true, false) => {
                    self.e0[i] += c.pair(k, alpha, fj);
                    self.e1[i] += c.pair(k, beta, fj);
                }
                (false, true) => {
                    self.e0[j] += c.pair(k, fi, alpha);
                    self.e1[j] += c.pair(k, fi, beta);
                }
                (false, false) => {}
            }
        }
        for i in 0..c.n {
            if in_set(labels[i]) {
                let (x0, x1) = (self.e0[i], self.e1[i]);
                let m = x0.min_of(x1);
                self.graph.update_tweights_unchecked(i, x1 - m, x0 - m);
            }
        }
        self.graph.maxflow();
        for i in 0..c.n {
            self.candidate[i] = if in_set(labels[i]) {
                if self.graph.is_sink_side(i) {
                    beta
                } else {
                    alpha
                }
            } else {
                labels[i]
            };
        }
        c.energy(&self.candidate)
    }
}
