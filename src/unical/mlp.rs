//! Small fully connected networks: ReLU hidden layers, a linear output layer (the caller applies
//! output activations: sigmoid for colour, none for the SDF). Forward keeps the activations a
//! backward pass needs; backward accumulates parameter gradients (per thread, merged per step)
//! and returns d(loss)/d(input). f32 throughout: these are the hot arrays (method.md §18).
//! The `_many` forms run a batch of samples through each layer as one small matrix product
//! ([`super::gemm`]), which is how the hot paths call them.

use std::sync::{Arc, OnceLock};

use super::gemm::{Shape, gemm_acc};

/// One layer: `y = W x + b`, W row-major `out × in`.
#[derive(Clone, Debug)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    weights: Vec<f32>,
    pub bias: Vec<f32>,
    /// W transposed (`in × out`, the layout a batched forward pass multiplies by), made on first
    /// use and dropped whenever the weights are borrowed mutably ([`Layer::weights_mut`]).
    transposed: OnceLock<Vec<f32>>,
}

impl PartialEq for Layer {
    fn eq(&self, other: &Self) -> bool {
        (self.inputs, self.outputs) == (other.inputs, other.outputs)
            && self.weights == other.weights
            && self.bias == other.bias
    }
}

impl Layer {
    /// A layer from W (row-major `outputs × inputs`) and b.
    pub fn new(inputs: usize, outputs: usize, weights: Vec<f32>, bias: Vec<f32>) -> Self {
        Self {
            inputs,
            outputs,
            weights,
            bias,
            transposed: OnceLock::new(),
        }
    }

    /// W, row-major `out × in`.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// W to change (the transposed copy is made again on next use).
    pub fn weights_mut(&mut self) -> &mut [f32] {
        self.transposed = OnceLock::new();
        &mut self.weights
    }

    /// W and b to change together (as [`Layer::weights_mut`]).
    pub fn params_mut(&mut self) -> (&mut [f32], &mut [f32]) {
        self.transposed = OnceLock::new();
        (&mut self.weights, &mut self.bias)
    }

    /// Wᵀ, row-major `in × out`.
    fn transposed(&self) -> &[f32] {
        self.transposed.get_or_init(|| {
            let (i_n, o_n) = (self.inputs, self.outputs);
            let mut t = vec![0.0; i_n * o_n];
            for (o, row) in self.weights.chunks_exact(i_n).enumerate() {
                for (i, w) in row.iter().enumerate() {
                    t[i * o_n + o] = *w;
                }
            }
            t
        })
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    pub layers: Vec<Layer>,
}

/// Gradients with the same shapes as the network's parameters (`default()`: no network, for
/// a decoder that is absent).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MlpGrad {
    pub weights: Vec<Vec<f32>>,
    pub bias: Vec<Vec<f32>>,
}

/// Activations of one forward pass, all in one row: the input (`input_len` values), then each
/// layer's output in turn (after ReLU for hidden layers); the network's widths say where each
/// one starts (`Mlp::activation`). A batch's rows share one buffer ([`Mlp::forward_many`]:
/// one allocation per batch, not per sample).
#[derive(Clone, Debug)]
pub struct Trace {
    data: Arc<[f32]>,
    /// Where this pass's row starts in `data`, and its length.
    start: usize,
    len: usize,
    input_len: usize,
    output_len: usize,
}

impl Default for Trace {
    fn default() -> Self {
        Self {
            data: Arc::from(Vec::new()),
            start: 0,
            len: 0,
            input_len: 0,
            output_len: 0,
        }
    }
}

impl Trace {
    fn values(&self) -> &[f32] {
        &self.data[self.start..self.start + self.len]
    }

    pub fn output(&self) -> &[f32] {
        let v = self.values();
        &v[v.len() - self.output_len..]
    }
}

impl Mlp {
    /// Layer widths `[in, hidden…, out]`, He-uniform weights from a seed, zero biases.
    pub fn new(widths: &[usize], seed: u64) -> Self {
        let mut state = seed ^ 0xD1B5_4A32_D192_ED03;
        let mut uniform = move || {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let layers = widths
            .windows(2)
            .map(|w| {
                let bound = (6.0 / w[0] as f32).sqrt();
                Layer::new(
                    w[0],
                    w[1],
                    (0..w[0] * w[1]).map(|_| uniform() * bound).collect(),
                    vec![0.0; w[1]],
                )
            })
            .collect();
        Self { layers }
    }

    pub fn input_dim(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }

    pub fn output_dim(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }

    pub fn zero_grad(&self) -> MlpGrad {
        MlpGrad {
            weights: self
                .layers
                .iter()
                .map(|l| vec![0.0; l.weights.len()])
                .collect(),
            bias: self
                .layers
                .iter()
                .map(|l| vec![0.0; l.bias.len()])
                .collect(),
        }
    }

    /// Activation `k` of `trace` (0: the input, k: layer k−1's output).
    fn activation<'a>(&self, trace: &'a Trace, k: usize) -> &'a [f32] {
        if k == 0 {
            return &trace.values()[..trace.input_len];
        }
        let start = trace.input_len
            + self.layers[..k - 1]
                .iter()
                .map(|l| l.outputs)
                .sum::<usize>();
        &trace.values()[start..start + self.layers[k - 1].outputs]
    }

    /// Forward pass keeping the activations.
    pub fn forward(&self, input: &[f32]) -> Trace {
        self.forward_from(input.len(), |x| x.copy_from_slice(input))
    }

    /// Forward pass on an input of `input_len` values that `write_input` writes in place (an
    /// encoding straight into the trace, without a buffer of its own).
    pub fn forward_from(&self, input_len: usize, write_input: impl FnOnce(&mut [f32])) -> Trace {
        let total = input_len + self.layers.iter().map(|l| l.outputs).sum::<usize>();
        let mut data = vec![0.0; total];
        write_input(&mut data[..input_len]);
        let last = self.layers.len().saturating_sub(1);
        let (mut start, mut end) = (0, input_len);
        for (k, layer) in self.layers.iter().enumerate() {
            let (done, rest) = data.split_at_mut(end);
            let x = &done[start..];
            let y = &mut rest[..layer.outputs];
            y.copy_from_slice(&layer.bias);
            for (yo, row) in y.iter_mut().zip(layer.weights.chunks_exact(layer.inputs)) {
                *yo += dot(row, x);
                if k < last {
                    *yo = yo.max(0.0);
                }
            }
            (start, end) = (end, end + layer.outputs);
        }
        let len = data.len();
        Trace {
            data: Arc::from(data),
            start: 0,
            len,
            input_len,
            output_len: if self.layers.is_empty() {
                input_len
            } else {
                self.output_dim()
            },
        }
    }

    /// Backward pass: accumulate parameter gradients into `grad`, return d(loss)/d(input).
    pub fn backward(&self, trace: &Trace, d_output: &[f32], grad: &mut MlpGrad) -> Vec<f32> {
        let widest = self.layers.iter().map(|l| l.inputs).max().unwrap_or(0);
        let mut delta = Vec::with_capacity(widest.max(d_output.len()));
        delta.extend_from_slice(d_output);
        let mut d_in = Vec::with_capacity(widest);
        let last = self.layers.len().saturating_sub(1);
        for k in (0..self.layers.len()).rev() {
            let layer = &self.layers[k];
            if k < last {
                // ReLU: no gradient where the unit was off.
                for (d, a) in delta.iter_mut().zip(self.activation(trace, k + 1)) {
                    if *a <= 0.0 {
                        *d = 0.0;
                    }
                }
            }
            let x = &self.activation(trace, k)[..layer.inputs];
            d_in.clear();
            d_in.resize(layer.inputs, 0.0);
            let rows = layer.weights.chunks_exact(layer.inputs);
            let grad_rows = grad.weights[k].chunks_exact_mut(layer.inputs);
            for (((&d, w), g), b) in delta.iter().zip(rows).zip(grad_rows).zip(&mut grad.bias[k]) {
                if d == 0.0 {
                    continue;
                }
                *b += d;
                // Element-wise (no reductions), so these vectorise.
                for (gi, xi) in g.iter_mut().zip(x) {
                    *gi += d * xi;
                }
                for (di, wi) in d_in.iter_mut().zip(w) {
                    *di += d * wi;
                }
            }
            std::mem::swap(&mut delta, &mut d_in);
        }
        delta
    }
}

impl Mlp {
    /// Forward passes of `n` inputs at once (`inputs` row-major, `n × input_dim`): each layer
    /// one matrix product ([`super::gemm`]). The traces are those [`Mlp::forward`] gives, but
    /// for rounding.
    pub fn forward_many(&self, n: usize, inputs: &[f32]) -> Vec<Trace> {
        let input_len = self.input_dim();
        let widths: Vec<usize> = self.layers.iter().map(|l| l.outputs).collect();
        let mut acts: Vec<Vec<f32>> = Vec::with_capacity(self.layers.len() + 1);
        acts.push(inputs[..n * input_len].to_vec());
        let last = self.layers.len().saturating_sub(1);
        for (k, layer) in self.layers.iter().enumerate() {
            let (i_n, o_n) = (layer.inputs, layer.outputs);
            let mut y = Vec::with_capacity(n * o_n);
            for _ in 0..n {
                y.extend_from_slice(&layer.bias);
            }
            gemm_acc(
                Shape::row_major(n, i_n, o_n),
                &acts[k],
                layer.transposed(),
                &mut y,
            );
            if k < last {
                y.iter_mut().for_each(|v| *v = v.max(0.0));
            }
            acts.push(y);
        }
        let total = input_len + widths.iter().sum::<usize>();
        let mut data = Vec::with_capacity(n * total);
        for s in 0..n {
            for (k, a) in acts.iter().enumerate() {
                let w = if k == 0 { input_len } else { widths[k - 1] };
                data.extend_from_slice(&a[s * w..(s + 1) * w]);
            }
        }
        let data: Arc<[f32]> = Arc::from(data);
        let output_len = if self.layers.is_empty() {
            input_len
        } else {
            self.output_dim()
        };
        (0..n)
            .map(|s| Trace {
                data: Arc::clone(&data),
                start: s * total,
                len: total,
                input_len,
                output_len,
            })
            .collect()
    }

    /// Backward passes of several forward passes at once (`d_outputs` row-major,
    /// `traces.len() × output_dim`): accumulates the parameter gradients into `grad` and
    /// returns d(loss)/d(input), row-major `traces.len() × input_dim`. Each layer's weight
    /// gradient and input gradient are one matrix product each.
    pub fn backward_many(
        &self,
        traces: &[&Trace],
        d_outputs: &[f32],
        grad: &mut MlpGrad,
    ) -> Vec<f32> {
        let n = traces.len();
        let mut delta = d_outputs[..n * self.output_dim()].to_vec();
        let last = self.layers.len().saturating_sub(1);
        let mut x = Vec::new();
        for k in (0..self.layers.len()).rev() {
            let layer = &self.layers[k];
            let (i_n, o_n) = (layer.inputs, layer.outputs);
            if k < last {
                // ReLU: no gradient where the unit was off.
                for (s, t) in traces.iter().enumerate() {
                    let a = self.activation(t, k + 1);
                    for (d, a) in delta[s * o_n..(s + 1) * o_n].iter_mut().zip(a) {
                        if *a <= 0.0 {
                            *d = 0.0;
                        }
                    }
                }
            }
            for row in delta.chunks_exact(o_n) {
                for (b, d) in grad.bias[k].iter_mut().zip(row) {
                    *b += d;
                }
            }
            x.clear();
            for t in traces {
                x.extend_from_slice(&self.activation(t, k)[..i_n]);
            }
            // ∂L/∂W += δᵀ·X, ∂L/∂x = δ·W.
            gemm_acc(
                Shape::transposed(o_n, n, i_n),
                &delta,
                &x,
                &mut grad.weights[k],
            );
            let mut d_in = vec![0.0; n * i_n];
            gemm_acc(
                Shape::row_major(n, o_n, i_n),
                &delta,
                &layer.weights,
                &mut d_in,
            );
            delta = d_in;
        }
        delta
    }
}

/// Dot product with eight independent partial sums: a single running sum is a chain of
/// dependent adds the compiler may not reorder (and so cannot vectorise).
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    acc.iter().sum::<f32>() + tail
}

impl MlpGrad {
    pub fn add(&mut self, other: &MlpGrad) {
        for (a, b) in self.weights.iter_mut().zip(&other.weights) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        for (a, b) in self.bias.iter_mut().zip(&other.bias) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn loss(m: &Mlp, x: &[f32], w: &[f32]) -> f32 {
        m.forward(x)
            .output()
            .iter()
            .zip(w)
            .map(|(a, b)| a * b)
            .sum()
    }

    #[test]
    fn backward_matches_finite_differences() {
        let mut m = Mlp::new(&[5, 8, 8, 3], 1);
        for l in &mut m.layers {
            for (i, b) in l.bias.iter_mut().enumerate() {
                *b = 0.1 * (i as f32 % 3.0) - 0.05;
            }
        }
        let x = [0.3, -0.7, 0.5, 0.9, -0.2];
        let w = [0.7, -1.1, 0.4];
        let trace = m.forward(&x);
        let mut grad = m.zero_grad();
        let d_in = m.backward(&trace, &w, &mut grad);
        let eps = 1e-3;
        for k in 0..m.layers.len() {
            for i in (0..m.layers[k].weights.len()).step_by(5) {
                let p0 = m.layers[k].weights()[i];
                m.layers[k].weights_mut()[i] = p0 + eps;
                let up = loss(&m, &x, &w);
                m.layers[k].weights_mut()[i] = p0 - eps;
                let down = loss(&m, &x, &w);
                m.layers[k].weights_mut()[i] = p0;
                let fd = (up - down) / (2.0 * eps);
                assert!(
                    (fd - grad.weights[k][i]).abs() < 2e-3 * (1.0 + fd.abs()),
                    "W{k}[{i}] {fd} vs {}",
                    grad.weights[k][i]
                );
            }
            for i in 0..m.layers[k].bias.len() {
                let p0 = m.layers[k].bias[i];
                m.layers[k].bias[i] = p0 + eps;
                let up = loss(&m, &x, &w);
                m.layers[k].bias[i] = p0 - eps;
                let down = loss(&m, &x, &w);
                m.layers[k].bias[i] = p0;
                let fd = (up - down) / (2.0 * eps);
                assert!(
                    (fd - grad.bias[k][i]).abs() < 2e-3 * (1.0 + fd.abs()),
                    "b{k}[{i}]"
                );
            }
        }
        for i in 0..x.len() {
            let mut up = x;
            up[i] += eps;
            let mut down = x;
            down[i] -= eps;
            let fd = (loss(&m, &up, &w) - loss(&m, &down, &w)) / (2.0 * eps);
            assert!(
                (fd - d_in[i]).abs() < 2e-3 * (1.0 + fd.abs()),
                "x[{i}] {fd} vs {}",
                d_in[i]
            );
        }
    }

    /// A batch through `forward_many` and `backward_many` gives each sample's trace and input
    /// gradient, and the sum of the parameter gradients, of one pass at a time.
    #[test]
    fn batched_passes_match_one_at_a_time() {
        let mut m = Mlp::new(&[6, 20, 9, 5], 3);
        for l in &mut m.layers {
            for (i, b) in l.bias.iter_mut().enumerate() {
                *b = 0.1 * (i as f32 % 3.0) - 0.1;
            }
        }
        let n = 11;
        let inputs: Vec<f32> = (0..n * 6)
            .map(|i| ((i as f32) * 0.618).fract() - 0.4)
            .collect();
        let d_out: Vec<f32> = (0..n * 5)
            .map(|i| ((i as f32) * 0.377).fract() - 0.5)
            .collect();
        let traces = m.forward_many(n, &inputs);
        let mut one_grad = m.zero_grad();
        let mut one_d_in = Vec::new();
        for s in 0..n {
            let t = m.forward(&inputs[s * 6..(s + 1) * 6]);
            for (a, b) in t.values().iter().zip(traces[s].values()) {
                assert!((a - b).abs() < 1e-5, "sample {s}: {a} vs {b}");
            }
            one_d_in.extend(m.backward(&t, &d_out[s * 5..(s + 1) * 5], &mut one_grad));
        }
        let mut grad = m.zero_grad();
        let refs: Vec<&Trace> = traces.iter().collect();
        let d_in = m.backward_many(&refs, &d_out, &mut grad);
        let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-4);
        assert!(close(&d_in, &one_d_in));
        for k in 0..m.layers.len() {
            assert!(close(&grad.weights[k], &one_grad.weights[k]), "W{k}");
            assert!(close(&grad.bias[k], &one_grad.bias[k]), "b{k}");
        }
    }

    /// The batched pass multiplies by a cached Wᵀ: a change through `weights_mut` (as an
    /// optimiser step or a finite-difference probe makes) is seen by the next pass.
    #[test]
    fn batched_pass_sees_changed_weights() {
        let mut m = Mlp::new(&[5, 16, 3], 4);
        let inputs: Vec<f32> = (0..2 * 5).map(|i| (i as f32 * 0.37).sin()).collect();
        let before = m.forward_many(2, &inputs)[1].output().to_vec();
        for w in m.layers[0].weights_mut() {
            *w *= 1.5;
        }
        let after = m.forward_many(2, &inputs)[1].output().to_vec();
        let fresh = m.clone().forward(&inputs[5..]).output().to_vec();
        assert_ne!(before, after);
        for (a, f) in after.iter().zip(&fresh) {
            assert!((a - f).abs() < 1e-5, "{a} vs {f}");
        }
    }

    #[test]
    fn shapes_and_determinism() {
        let a = Mlp::new(&[32, 64, 64, 16], 9);
        let b = Mlp::new(&[32, 64, 64, 16], 9);
        assert_eq!(a, b);
        assert_eq!((a.input_dim(), a.output_dim()), (32, 16));
        assert_eq!(a.forward(&[0.1; 32]).output().len(), 16);
    }
}
