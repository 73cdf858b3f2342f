//! Small fully connected networks: ReLU hidden layers, a linear output layer (the caller applies
//! output activations: sigmoid for colour, none for the SDF). Forward keeps the activations a
//! backward pass needs; backward accumulates parameter gradients (per thread, merged per step)
//! and returns d(loss)/d(input). f32 throughout: these are the hot arrays (method.md §18).

/// One layer: `y = W x + b`, W row-major `out × in`.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
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

/// Activations of one forward pass, all in one buffer (one allocation per sample on the hot
/// path): the input (`input_len` values), then each layer's output in turn (after ReLU for
/// hidden layers); the network's widths say where each one starts (`Mlp::activation`).
#[derive(Clone, Debug, Default)]
pub struct Trace {
    data: Vec<f32>,
    input_len: usize,
    output_len: usize,
}

impl Trace {
    pub fn output(&self) -> &[f32] {
        &self.data[self.data.len() - self.output_len..]
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
                Layer {
                    inputs: w[0],
                    outputs: w[1],
                    weights: (0..w[0] * w[1]).map(|_| uniform() * bound).collect(),
                    bias: vec![0.0; w[1]],
                }
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
            return &trace.data[..trace.input_len];
        }
        let start = trace.input_len
            + self.layers[..k - 1]
                .iter()
                .map(|l| l.outputs)
                .sum::<usize>();
        &trace.data[start..start + self.layers[k - 1].outputs]
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
        Trace {
            data,
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
                let p0 = m.layers[k].weights[i];
                m.layers[k].weights[i] = p0 + eps;
                let up = loss(&m, &x, &w);
                m.layers[k].weights[i] = p0 - eps;
                let down = loss(&m, &x, &w);
                m.layers[k].weights[i] = p0;
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

    #[test]
    fn shapes_and_determinism() {
        let a = Mlp::new(&[32, 64, 64, 16], 9);
        let b = Mlp::new(&[32, 64, 64, 16], 9);
        assert_eq!(a, b);
        assert_eq!((a.input_dim(), a.output_dim()), (32, 16));
        assert_eq!(a.forward(&[0.1; 32]).output().len(), 16);
    }
}
