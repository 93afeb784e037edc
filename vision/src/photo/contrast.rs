//! The contrast between printed material and plate, chosen per photo from its colour.
//!
//! Grey filament on a gold plate has almost no grey contrast while its colour differs, and
//! a specular or textured plate varies far more in brightness than in hue; so the photo is
//! not read as grey but projected on Fisher's discriminant direction of its two classes,
//! w = S_w⁻¹ (m₁ − m₀) in RGB (S_w the pooled within-class covariance), scaled so that the
//! plate's mean reads 0 and the print's 1. Before the photo is placed on the bed the two
//! classes come from two-means clustering started at the ends of the first principal
//! component ([`ColourAxis::from_clusters`]); once it is placed, from the pixels the G-code
//! says are print and plate ([`ColourAxis::from_labels`]), which also fixes the polarity.

use rayon::prelude::*;

use super::image::ColourImage;
use crate::lines::GrayImage;

/// Pixels sampled for the clustering (evenly strided over the photo).
const CLUSTER_SAMPLES: usize = 40_000;
/// Two-means iterations (it settles in a few).
const CLUSTER_ITERATIONS: usize = 25;
/// Ridge added to the within-class covariance's diagonal, relative to its trace, so a
/// channel without variance (a grey photo's equal channels) leaves it invertible.
const COVARIANCE_RIDGE: f64 = 1e-4;

/// A projection of RGB on one direction: `value = direction · (rgb − origin)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ColourAxis {
    /// The colour that reads 0 (the plate's mean, once labelled).
    pub origin: [f64; 3],
    /// The direction, scaled so that the other class's mean reads 1.
    pub direction: [f64; 3],
    /// Fisher's separation of the two classes: the distance of their means in pooled
    /// within-class standard deviations along the direction.
    pub separation: f64,
}

/// Running sums of one class's colours.
#[derive(Debug, Clone, Copy, Default)]
struct ClassSums {
    n: f64,
    sum: [f64; 3],
    outer: [[f64; 3]; 3],
}

/// Running sums of labelled colours, plate and print, from which
/// [`ColourAxis::from_label_sums`] learns the axis. Sums over parts of an image merged in a
/// fixed order give the same axis whatever the threads that summed the parts.
#[derive(Debug, Clone, Copy, Default)]
pub struct LabelSums {
    classes: [ClassSums; 2],
}

impl LabelSums {
    /// Adds one colour, `is_print` its label.
    #[inline]
    pub fn add(&mut self, colour: [f32; 3], is_print: bool) {
        self.classes[usize::from(is_print)].add(colour);
    }

    /// Adds the colours `other` holds.
    pub fn merge(&mut self, other: &LabelSums) {
        for (mine, theirs) in self.classes.iter_mut().zip(&other.classes) {
            mine.n += theirs.n;
            for a in 0..3 {
                mine.sum[a] += theirs.sum[a];
                for b in 0..3 {
                    mine.outer[a][b] += theirs.outer[a][b];
                }
            }
        }
    }
}

impl ClassSums {
    fn add(&mut self, c: [f32; 3]) {
        let c = c.map(f64::from);
        self.n += 1.0;
        for a in 0..3 {
            self.sum[a] += c[a];
            for b in 0..3 {
                self.outer[a][b] += c[a] * c[b];
            }
        }
    }

    fn mean(&self) -> [f64; 3] {
        self.sum.map(|s| s / self.n.max(1.0))
    }

    /// Scatter about the mean (n × covariance).
    fn scatter(&self) -> [[f64; 3]; 3] {
        let m = self.mean();
        let mut s = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                s[a][b] = self.outer[a][b] - self.n * m[a] * m[b];
            }
        }
        s
    }
}

impl ColourAxis {
    /// The axis separating the photo's two colour clusters (no labels); which one is the
    /// print is not known, so the sign is arbitrary. `None` if the photo has one colour.
    pub fn from_clusters(img: &ColourImage) -> Option<Self> {
        let stride = (img.pixels.len() / CLUSTER_SAMPLES).max(1);
        let samples: Vec<[f32; 3]> = img.pixels.iter().step_by(stride).copied().collect();
        let mut centres = principal_extremes(&samples)?;
        let mut classes = [ClassSums::default(); 2];
        for _ in 0..CLUSTER_ITERATIONS {
            classes = [ClassSums::default(); 2];
            for &c in &samples {
                classes[nearest(&centres, c)].add(c);
            }
            if classes.iter().any(|k| k.n == 0.0) {
                return None;
            }
            let moved = [classes[0].mean(), classes[1].mean()];
            if moved == centres {
                // settled: every further iteration would give the same classes
                break;
            }
            centres = moved;
        }
        Self::fisher(&classes[0], &classes[1])
    }

    /// The axis from labelled colours (`true` for print): plate reads 0 and print 1.
    pub fn from_labels(labelled: impl IntoIterator<Item = ([f32; 3], bool)>) -> Option<Self> {
        let mut sums = LabelSums::default();
        for (colour, is_print) in labelled {
            sums.add(colour, is_print);
        }
        Self::from_label_sums(&sums)
    }

    /// [`Self::from_labels`] from the labelled colours' sums.
    pub fn from_label_sums(sums: &LabelSums) -> Option<Self> {
        Self::fisher(&sums.classes[0], &sums.classes[1])
    }

    /// The photo projected on the axis.
    pub fn apply(&self, img: &ColourImage) -> GrayImage {
        let pixels = img.pixels.par_iter().map(|&c| self.value(c) as f32).collect();
        GrayImage { width: img.width, height: img.height, pixels }
    }

    /// The value of one colour.
    #[inline]
    pub fn value(&self, c: [f32; 3]) -> f64 {
        (0..3).map(|k| self.direction[k] * (f64::from(c[k]) - self.origin[k])).sum()
    }

    fn fisher(zero: &ClassSums, one: &ClassSums) -> Option<Self> {
        if zero.n < 2.0 || one.n < 2.0 {
            return None;
        }
        let (m0, m1) = (zero.mean(), one.mean());
        let (s0, s1) = (zero.scatter(), one.scatter());
        let mut pooled = [[0.0; 3]; 3];
        for a in 0..3 {
            for b in 0..3 {
                pooled[a][b] = (s0[a][b] + s1[a][b]) / (zero.n + one.n - 2.0);
            }
        }
        let ridge = COVARIANCE_RIDGE * (pooled[0][0] + pooled[1][1] + pooled[2][2]).max(1e-12);
        for a in 0..3 {
            pooled[a][a] += ridge;
        }
        let diff = [m1[0] - m0[0], m1[1] - m0[1], m1[2] - m0[2]];
        let w = solve3(pooled, diff)?;
        let gap: f64 = (0..3).map(|k| w[k] * diff[k]).sum();
        if gap.is_nan() || gap <= 0.0 || gap.is_infinite() {
            return None;
        }
        // wᵀ S w = wᵀ diff = gap, so the separation in pooled sd is gap / √gap.
        Some(Self { origin: m0, direction: w.map(|v| v / gap), separation: gap.sqrt() })
    }
}

/// The samples at the two ends of the first principal component (power iteration on the
/// covariance), as the clustering's start.
fn principal_extremes(samples: &[[f32; 3]]) -> Option<[[f64; 3]; 2]> {
    let mut all = ClassSums::default();
    samples.iter().for_each(|&c| all.add(c));
    let (m, s) = (all.mean(), all.scatter());
    let mut v = [1.0, 1.0, 1.0];
    for _ in 0..50 {
        let next = [0, 1, 2].map(|a| (0..3).map(|b| s[a][b] * v[b]).sum::<f64>());
        let norm = next.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        v = next.map(|x| x / norm);
    }
    let along = |c: &[f32; 3]| (0..3).map(|k| (f64::from(c[k]) - m[k]) * v[k]).sum::<f64>();
    let lo = samples.iter().min_by(|a, b| along(a).total_cmp(&along(b)))?;
    let hi = samples.iter().max_by(|a, b| along(a).total_cmp(&along(b)))?;
    Some([lo.map(f64::from), hi.map(f64::from)])
}

fn nearest(centres: &[[f64; 3]; 2], c: [f32; 3]) -> usize {
    let d = |m: &[f64; 3]| (0..3).map(|k| (f64::from(c[k]) - m[k]).powi(2)).sum::<f64>();
    usize::from(d(&centres[1]) < d(&centres[0]))
}

/// Solves the symmetric 3 × 3 system `a x = b` by Cramer's rule; `None` if singular.
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if d.abs() < 1e-300 {
        return None;
    }
    let mut x = [0.0; 3];
    for k in 0..3 {
        let mut m = a;
        for r in 0..3 {
            m[r][k] = b[r];
        }
        x[k] = det(m) / d;
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Grey filament on a gold plate: equal luma, different hue; the plate's brightness
    /// varies (a lighting ramp) far more than either colour's noise.
    fn grey_on_gold() -> (ColourImage, impl Fn(usize, usize) -> bool) {
        let (w, h) = (64, 48);
        let is_print = |i: usize, _j: usize| (20..30).contains(&i);
        let pixels = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                let light = 0.8 + 0.4 * j as f32 / h as f32;
                let gold = [0.62, 0.52, 0.25];
                let grey = [0.51, 0.51, 0.51];
                let c = if is_print(i, j) { grey } else { gold };
                c.map(|v| v * light)
            })
            .collect();
        (ColourImage::new(w, h, pixels).unwrap(), is_print)
    }

    #[test]
    fn clusters_separate_grey_filament_from_a_gold_plate() {
        let (img, is_print) = grey_on_gold();
        let axis = ColourAxis::from_clusters(&img).unwrap();
        let contrast = axis.apply(&img);
        let value = |i: usize, j: usize| contrast.at(i, j);
        // every print pixel on one side of every plate pixel, whatever the lighting
        let (mut print, mut plate) = (Vec::new(), Vec::new());
        for j in 0..img.height {
            for i in 0..img.width {
                if is_print(i, j) {
                    print.push(value(i, j))
                } else {
                    plate.push(value(i, j))
                }
            }
        }
        let (pmin, pmax) =
            (print.iter().cloned().fold(f32::MAX, f32::min), print.iter().cloned().fold(f32::MIN, f32::max));
        let (bmin, bmax) =
            (plate.iter().cloned().fold(f32::MAX, f32::min), plate.iter().cloned().fold(f32::MIN, f32::max));
        assert!(pmin > bmax || pmax < bmin, "print {pmin}..{pmax}, plate {bmin}..{bmax}");
    }

    #[test]
    fn labels_put_the_plate_at_zero_and_the_print_at_one() {
        let (img, is_print) = grey_on_gold();
        let labelled = (0..img.height).flat_map(|j| (0..img.width).map(move |i| (i, j)));
        let axis = ColourAxis::from_labels(labelled.map(|(i, j)| (img.at(i, j), is_print(i, j)))).unwrap();
        let contrast = axis.apply(&img);
        let mean = |pred: &dyn Fn(usize, usize) -> bool| {
            let v: Vec<f64> = (0..img.height)
                .flat_map(|j| (0..img.width).map(move |i| (i, j)))
                .filter(|&(i, j)| pred(i, j))
                .map(|(i, j)| f64::from(contrast.at(i, j)))
                .collect();
            v.iter().sum::<f64>() / v.len() as f64
        };
        assert!((mean(&|i, j| is_print(i, j)) - 1.0).abs() < 1e-4);
        assert!(mean(&|i, j| !is_print(i, j)).abs() < 1e-4);
        assert!(axis.separation > 5.0);
    }

    #[test]
    fn a_single_colour_has_no_axis() {
        let img = ColourImage::new(10, 10, vec![[0.3, 0.3, 0.3]; 100]).unwrap();
        assert!(ColourAxis::from_clusters(&img).is_none());
        assert!(ColourAxis::from_labels(img.pixels.iter().enumerate().map(|(k, &c)| (c, k % 10 < 5))).is_none());
    }
}
