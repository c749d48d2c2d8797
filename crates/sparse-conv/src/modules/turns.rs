//! Quarter turns about the vertical axis: weights tied so that a network answers a cloud turned by
//! 90° with its answer turned by 90° (a p4 group convolution, Cohen & Welling 2016, on a 3D
//! lattice turning about z).
//!
//! Conventions, which every function here shares:
//! - A turn maps (x, y) to (−y, x). On the voxel lattice it maps index (i, j) to (−j − 1, i): a
//!   turn about the corner that every level's cells share, so that each coarser level's 2×2 blocks
//!   map onto blocks and the strided convolutions stay exact.
//! - A kernel offset (a, b, c) of a size-K kernel (indices 0..K, x-major) maps to (K − 1 − b, a, c):
//!   one rule for the odd submanifold kernels (about their centre) and the even strided ones
//!   (about the block's centre).
//! - Regular features hold [`TURNS`] orientation copies of `c` channels, orientation-major:
//!   channel `r·c + i` is copy r's channel i. A turn of the input moves copy r to copy r + 1.

use burn::tensor::{Device, Int, Tensor, TensorData};

/// The orientations: four quarter turns.
pub const TURNS: usize = 4;

/// How plain channels change under one quarter turn: channel `a` of the turned features is
/// `sign[a]` times channel `source[a]` before it (a signed permutation: a vector's (x, y) becomes
/// (−y, x), a heading's bins shift by a quarter turn, a scalar stays).
#[derive(Debug, Clone, PartialEq)]
pub struct FieldTurn {
    source: Vec<usize>,
    sign: Vec<f32>,
}

impl FieldTurn {
    /// `n` channels that a turn leaves as they are.
    pub fn scalars(n: usize) -> Self {
        Self { source: (0..n).collect(), sign: vec![1.0; n] }
    }

    /// Channels `x` and `y` turn as a vector: (x, y) → (−y, x).
    pub fn with_vector(mut self, x: usize, y: usize) -> Self {
        (self.source[x], self.sign[x]) = (y, -1.0);
        (self.source[y], self.sign[y]) = (x, 1.0);
        self
    }

    /// Channels `start..start + len` cycle forward by `shift` under a turn (bins of an angle):
    /// the turned channel `start + j` is the channel `start + (j − shift) mod len` before.
    pub fn with_cycle(mut self, start: usize, len: usize, shift: usize) -> Self {
        for j in 0..len {
            (self.source[start + j], self.sign[start + j]) = (start + (j + len - shift % len) % len, 1.0);
        }
        self
    }

    /// Number of channels.
    pub fn len(&self) -> usize {
        self.source.len()
    }

    /// Whether it has no channels.
    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }

    /// `r` quarter turns, as one signed permutation.
    pub fn power(&self, r: usize) -> FieldTurn {
        let mut out = Self::scalars(self.len());
        for _ in 0..r % TURNS {
            let (source, sign) = (0..self.len()).map(|a| (out.source[self.source[a]], self.sign[a] * out.sign[self.source[a]])).unzip();
            out = FieldTurn { source, sign };
        }
        out
    }

    /// The turned channels of `values` (`len()` per row).
    pub fn apply<T: Copy + From<f32> + std::ops::Mul<Output = T>>(&self, values: &[T]) -> Vec<T> {
        values.chunks(self.len()).flat_map(|row| (0..self.len()).map(move |a| T::from(self.sign[a]) * row[self.source[a]])).collect()
    }
}

/// Offset `k` (x-major over `size³`) of a size-`size` kernel turned `r` quarter turns.
pub fn turned_offset(size: usize, k: usize, r: usize) -> usize {
    let (mut a, mut b, c) = (k / (size * size), (k / size) % size, k % size);
    for _ in 0..r % TURNS {
        (a, b) = (size - 1 - b, a);
    }
    (a * size + b) * size + c
}

/// A convolution's full `[K, C_in, C_out]` weights built from fewer free weights, so that the
/// convolution commutes with quarter turns: every full entry is a free entry, maybe negated.
#[derive(Clone, PartialEq)]
pub struct TiedKernel {
    index: Vec<i64>,
    sign: Option<Vec<f32>>,
    free: [usize; 3],
    full: [usize; 3],
}

/// The shapes only: the index holds an entry per full weight.
impl std::fmt::Debug for TiedKernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TiedKernel").field("free", &self.free).field("full", &self.full).field("signed", &self.sign.is_some()).finish()
    }
}

impl TiedKernel {
    /// Between regular features: free `[K, 4·c_in, c_out]` (the kernel seen by output copy 0,
    /// input copies by their turn relative to it) to full `[K, 4·c_in, 4·c_out]`. Output copy r
    /// sees the kernel turned r times and the input copies cycled by r:
    /// `W[k, (s, i), (r, o)] = free[turn⁻ʳ(k), ((s − r) mod 4, i), o]`.
    pub fn regular(size: usize, c_in: usize, c_out: usize) -> Self {
        let volume = size.pow(3);
        let (full_in, full_out) = (TURNS * c_in, TURNS * c_out);
        let mut index = Vec::with_capacity(volume * full_in * full_out);
        for k in 0..volume {
            for s in 0..TURNS {
                for i in 0..c_in {
                    for r in 0..TURNS {
                        let kf = turned_offset(size, k, TURNS - r);
                        let row = ((s + TURNS - r) % TURNS) * c_in + i;
                        for o in 0..c_out {
                            index.push(((kf * full_in + row) * c_out + o) as i64);
                        }
                    }
                }
            }
        }
        Self { index, sign: None, free: [volume, full_in, c_out], full: [volume, full_in, full_out] }
    }

    /// From plain input channels that turn as `input` says to regular features (the first
    /// layer): free `[K, n, c_out]` to full `[K, n, 4·c_out]`. Output copy r sees the kernel
    /// turned r times and the input turned back r times:
    /// `W[k, i, (r, o)] = Σₐ M[a][i] · free[turn⁻ʳ(k), a, o]` with `M` the signed permutation of
    /// `input.power(4 − r)`.
    pub fn lifting(size: usize, input: &FieldTurn, c_out: usize) -> Self {
        let volume = size.pow(3);
        let n = input.len();
        let back: Vec<FieldTurn> = (0..TURNS).map(|r| input.power(TURNS - r)).collect();
        let mut index = Vec::with_capacity(volume * n * TURNS * c_out);
        let mut sign = Vec::with_capacity(index.capacity());
        for k in 0..volume {
            for i in 0..n {
                for (r, m) in back.iter().enumerate() {
                    let kf = turned_offset(size, k, TURNS - r);
                    // The row a of M that reads input channel i (a permutation has exactly one).
                    let a = m.source.iter().position(|&src| src == i).expect("a signed permutation");
                    for o in 0..c_out {
                        index.push(((kf * n + a) * c_out + o) as i64);
                        sign.push(m.sign[a]);
                    }
                }
            }
        }
        Self { index, sign: Some(sign), free: [volume, n, c_out], full: [volume, n, TURNS * c_out] }
    }

    /// From regular features to plain output channels that turn as `output` says, per voxel (a
    /// head): free `[c_in, n]` to full `[4·c_in, n]`, the mean over the copies of each copy's
    /// output turned forward by its orientation:
    /// `W[(r, i), a] = ¼ · sign_r[a] · free[i, source_r[a]]` with `output.power(r)`.
    pub fn pooling(c_in: usize, output: &FieldTurn) -> Self {
        let n = output.len();
        let mut index = Vec::with_capacity(TURNS * c_in * n);
        let mut sign = Vec::with_capacity(index.capacity());
        for r in 0..TURNS {
            let turn = output.power(r);
            for i in 0..c_in {
                for a in 0..n {
                    index.push((i * n + turn.source[a]) as i64);
                    sign.push(turn.sign[a] / TURNS as f32);
                }
            }
        }
        Self { index, sign: Some(sign), free: [1, c_in, n], full: [1, TURNS * c_in, n] }
    }

    /// Shape of the free weights.
    pub fn free_shape(&self) -> [usize; 3] {
        self.free
    }

    /// Shape of the full weights.
    pub fn full_shape(&self) -> [usize; 3] {
        self.full
    }

    /// The full weights from `free` (differentiable: each free weight's gradient is the sum over
    /// the full entries built from it).
    pub fn expand(&self, free: Tensor<3>) -> Tensor<3> {
        assert_eq!(free.dims(), self.free, "tied kernel: free weights of the wrong shape");
        let (device, dtype) = (free.device(), free.dtype());
        let flat: Tensor<1> = free.reshape([self.free.iter().product::<usize>()]);
        let mut full = flat.select(0, ints(&self.index, &device));
        if let Some(sign) = &self.sign {
            full = full * Tensor::<1>::from_data(TensorData::new(sign.clone(), [sign.len()]), (&device, dtype));
        }
        full.reshape(self.full)
    }
}

/// The mean of `bias` (`[n]`, plain channels turning as `output` says) over its four turns: the
/// part of a head's bias that a turn leaves unchanged (zero for a vector, equal for cycled bins).
pub fn pooled_bias(bias: Tensor<1>, output: &FieldTurn) -> Tensor<1> {
    let (device, dtype) = (bias.device(), bias.dtype());
    let n = output.len();
    let mut sum: Option<Tensor<1>> = None;
    for r in 0..TURNS {
        let turn = output.power(r);
        let index: Vec<i64> = turn.source.iter().map(|&s| s as i64).collect();
        let term = bias.clone().select(0, ints(&index, &device)) * Tensor::<1>::from_data(TensorData::new(turn.sign.clone(), [n]), (&device, dtype));
        sum = Some(match sum {
            Some(s) => s + term,
            None => term,
        });
    }
    sum.expect("four turns").div_scalar(TURNS as f32)
}

fn ints(v: &[i64], device: &Device) -> Tensor<1, Int> {
    Tensor::<1, Int>::from_data(TensorData::new(v.to_vec(), [v.len()]), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_turns_are_the_identity() {
        let f = FieldTurn::scalars(7).with_vector(1, 2).with_cycle(3, 4, 1);
        assert_eq!(f.power(4), FieldTurn::scalars(7));
        assert_eq!(f.power(1), f);
        // (x, y) = (1, 2) turned once is (−2, 1), twice (−1, −2).
        let v = [0.0, 1.0, 2.0, 10.0, 11.0, 12.0, 13.0];
        assert_eq!(f.apply(&v), vec![0.0, -2.0, 1.0, 13.0, 10.0, 11.0, 12.0]);
        assert_eq!(f.power(2).apply(&v), f.apply(&f.apply(&v)));
        for size in [1, 2, 3] {
            for k in 0..size * size * size {
                assert_eq!(turned_offset(size, turned_offset(size, k, 1), 3), k);
                assert_eq!(turned_offset(size, k, 4), k);
            }
        }
        // The 3×3 kernel's (+1, 0) neighbour turns to (0, +1): (2, 1, ·) → (1, 2, ·).
        assert_eq!(turned_offset(3, (2 * 3 + 1) * 3, 1), (1 * 3 + 2) * 3);
        // The 2×2 block's (1, 0) child turns to (1, 1), as the lattice map (i, j) → (−j − 1, i) sends
        // child (2I + 1, 2J) to (−2J − 1, 2I + 1) = 2·(−J − 1, I) + (1, 1).
        assert_eq!(turned_offset(2, (1 * 2) * 2, 1), (1 * 2 + 1) * 2);
    }
}
