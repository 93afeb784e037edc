//! Correspondence of detected corners with the known corners of the path, paper 003
//! Sec. 2.3: "the corners in the i-th thermal image and in the trajectory within R_i⁽¹⁾"
//! give the pairs (P⁽⁰⁾, P⁽¹⁾) of eq. 27.
//!
//! The recorded time t_r gives the approximate nozzle position and so, through the
//! nominal homography H0, the predicted pixel of each path corner. A detection and a
//! prediction are paired when each is the other's nearest neighbour and they lie within
//! a gate (px); the corner id travels with the pair. The paper does not say how it pairs
//! them; mutual nearest neighbours within a gate is the simplest rule that never pairs
//! one detection twice.

use crate::corners::CornerDetection;

/// A known path corner with its predicted position in the undistorted image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictedCorner {
    /// Caller's id of the path corner.
    pub id: u32,
    /// Corner position on the plane (world mm).
    pub plane_mm: [f64; 2],
    /// Predicted undistorted pixel.
    pub px: [f64; 2],
    /// Predicted undistorted pixels of the points [`ARM_PROBE_MM`] along each arm from
    /// the vertex (None when the arms are not known); used to locate the vertex from the
    /// bead ridges ([`crate::vertex`]).
    pub arm_px: Option<[[f64; 2]; 2]>,
}

/// Distance along each arm of the probe points of [`PredictedCorner::arm_px`] (mm).
pub const ARM_PROBE_MM: f64 = 1.0;

/// One accepted pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerMatch {
    /// Id of the path corner.
    pub id: u32,
    /// Index into the predicted corners.
    pub predicted: usize,
    /// Index into the detections.
    pub detection: usize,
    /// Distance between detection and prediction (px).
    pub distance_px: f64,
}

/// Mutual-nearest pairs within `gate_px`, written into `out` (cleared), ordered by
/// predicted index.
pub fn match_corners_into(
    detections: &[CornerDetection],
    predicted: &[PredictedCorner],
    gate_px: f64,
    out: &mut Vec<CornerMatch>,
) {
    out.clear();
    for (j, pred) in predicted.iter().enumerate() {
        let Some((i, dist)) = nearest(predicted_iter_px(detections), pred.px) else { continue };
        if dist > gate_px {
            continue;
        }
        let det_px = [detections[i].u_px, detections[i].v_px];
        let back = nearest(predicted.iter().map(|p| p.px), det_px);
        if back.map(|(k, _)| k) == Some(j) {
            out.push(CornerMatch { id: pred.id, predicted: j, detection: i, distance_px: dist });
        }
    }
}

/// Convenience wrapper returning a new vector.
pub fn match_corners(detections: &[CornerDetection], predicted: &[PredictedCorner], gate_px: f64) -> Vec<CornerMatch> {
    let mut out = Vec::new();
    match_corners_into(detections, predicted, gate_px, &mut out);
    out
}

fn predicted_iter_px(detections: &[CornerDetection]) -> impl Iterator<Item = [f64; 2]> + '_ {
    detections.iter().map(|d| [d.u_px, d.v_px])
}

/// Index and distance of the point nearest to `q` (first one on ties).
fn nearest(points: impl Iterator<Item = [f64; 2]>, q: [f64; 2]) -> Option<(usize, f64)> {
    points.enumerate().map(|(i, p)| (i, (p[0] - q[0]).hypot(p[1] - q[1]))).filter(|(_, d)| d.is_finite()).fold(
        None,
        |best, cur| match best {
            Some((_, bd)) if bd <= cur.1 => best,
            _ => Some(cur),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(u: f64, v: f64) -> CornerDetection {
        CornerDetection { u_px: u, v_px: v, temp_c: 145.0, score: 1.0 }
    }

    fn pred(id: u32, u: f64, v: f64) -> PredictedCorner {
        PredictedCorner { id, plane_mm: [0.0, 0.0], px: [u, v], arm_px: None }
    }

    #[test]
    fn pairs_keep_ids_and_respect_the_gate() {
        let dets = [det(10.0, 10.0), det(52.0, 40.0), det(100.0, 100.0)];
        let preds = [pred(7, 11.0, 10.0), pred(9, 50.0, 41.0), pred(3, 140.0, 20.0)];
        let m = match_corners(&dets, &preds, 5.0);
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].id, m[0].detection, m[0].distance_px), (7, 0, 1.0));
        assert_eq!((m[1].id, m[1].detection), (9, 1));
    }

    #[test]
    fn a_detection_is_never_paired_twice() {
        // Two predictions compete for one detection: only the nearer (mutual) one wins.
        let dets = [det(20.0, 20.0)];
        let preds = [pred(1, 22.0, 20.0), pred(2, 20.5, 20.0)];
        let m = match_corners(&dets, &preds, 5.0);
        assert_eq!(m.len(), 1);
        assert_eq!(m[0].id, 2);
    }

    #[test]
    fn no_detections_no_pairs() {
        assert!(match_corners(&[], &[pred(1, 0.0, 0.0)], 5.0).is_empty());
    }
}
