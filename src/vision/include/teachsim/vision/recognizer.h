// Model-based recognition of blocks in one camera image (paper §4, §4.1-4.3, §7.1): sub-pixel
// edges and straight segments, perceptual groups, an index over model views with approximate
// nearest-neighbour search (Beis & Lowe), pose by Lowe's iterative least squares on line-to-line
// residuals, verification, and the model editor's rules (rest on the table, no interpenetration).
//
// Frames: world (z up, table top z = 0 when a fixed world is given), camera (OpenCV axes, from
// Camera::world_T_camera), object (the box's centre, axes along its sides).
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "teachsim/base/status.h"
#include "teachsim/geometry/pose.h"
#include "teachsim/scene/scene.h"
#include "teachsim/vision/camera.h"

namespace teachsim::vision {

// A model of the library: blocks are boxes, centred on their object frame.
struct Model {
  std::string name;
  Eigen::Vector3d box_size_m = Eigen::Vector3d::Zero();  // full side lengths along object x, y, z, m
};

struct ModelLibrary {
  std::vector<Model> models;
};

// MODELS.json is either a scene file (each movable box-shaped object becomes a model, named by its
// `model` field when it has one, else by its name; equal names must have equal sizes) or
// {"models": [{"name": ..., "shape": shape}]} with shapes as in the scene format (boxes only).
// Errors name the file and the JSON path.
[[nodiscard]] Result<ModelLibrary> LoadModels(const std::string& path);
// A stable hash of the models' names and sizes (the index cache key, with the options).
uint64_t HashModelLibrary(const ModelLibrary& models);

struct RecognizerOptions {
  // --- lines (item 1)
  double canny_low = 16, canny_high = 40;    // Canny thresholds on the L2 magnitude of 3x3 Sobel derivatives (8x grey levels/px);
                                             // the high one seeds edges: at 100 the faint edges between two faces of a block
                                             // were never found (renders of seeds 7-9: 450 -> 519 of 567 blocks found at 40,
                                             // false positives 13 -> 11; 16 / 40 against 40 / 40: 519 against 499)
  double min_segment_length_px = 12;         // shorter segments are dropped, px
  double split_tolerance_px = 0.8;           // Ramer split: largest point-to-chord distance, px
  // --- grouping (item 2)
  double junction_gap_px = 12;               // endpoints closer than this (relative 0.25 of the shorter segment, whichever larger) are connected, px
                                             // (Canny rounds corners off and shadows cut edges short: at 8 px the groups of
                                             // many fully visible blocks were missing; 12-20 px all did better on the dev set)
  // --- index (item 3)
  int view_sphere_samples = 1200;            // viewing directions per model over the whole sphere (a quarter is kept, see BuildIndex)
  std::vector<double> view_distances_m = {0.45, 0.7};  // camera distances used for the model views, m
  int neighbours = 6;                        // k of the approximate k-nearest-neighbour search
  double index_search_eps = 1;               // approximate search (nanoflann): each neighbour within (1 + eps)
                                             // times the true one's distance; 0: exact. On seeds 7-19 0, 1 and 2
                                             // found the same blocks, one more than FLANN at 32 checks; 1.7 ms
                                             // per image (FLANN 6.8, exact 3)
  // Groups per kind looked up in the index, longest first (images with wood grain give up to 1000).
  // 150 until session 24; with 10 fits, 150 -> 50 on render seeds 7-41: found >= 0.7 visible 6308 ->
  // 6307, 0.4-0.7 165 -> 166, false 78 -> 75, the index stage about half the time.
  int max_index_queries = 50;
  int max_hypotheses = 10;                   // index hypotheses tried per image, most probable first, after the
                                             // support-plane ones (120 before that source, 60 until session 23).
                                             // Render seeds 7-18, 60/40/30/20/10/5: found >= 0.7 visible 2181/
                                             // 2180/2181/2181/2181/2180, 0.4-0.7 48/48/48/47/47/47, false 23/22/
                                             // 20/20/19/19; 10 held on seeds 19-31 (2335 -> 2338, 71 -> 71, false
                                             // 36 -> 32), fresh 32-41 (1791 -> 1789, 47 -> 47, 28 -> 27); the
                                             // fit-and-verify stage about a third faster
  // --- support-plane hypotheses (a second source beside the index, paper §7.1; blocks at rest, §4.3)
  bool support_hypotheses = true;            // off: the index alone proposes poses (the ablation)
  // Fitted per image, best edge support first. 40 until session 17; 80 on render seeds 7-31: found
  // >= 0.7 visible 4479 -> 4500 of 4738, 0.4-0.7 103 -> 110 of 372, false 68 -> 73 in 1500 images,
  // +0.9 ms per image (held out 19-31: +10, +4, +3 false; docs/benchmarks.md).
  int max_support_hypotheses = 80;
  // Placements behind an occluding contour (SupportHypotheses' behind_contour) come after those in
  // full view and take the room they leave under max_support_hypotheses, or this many places if that
  // is more, past the cap (in the cluttered images whose placements in full view fill it, a block half
  // hidden behind the contour gets no room). Off (0) by
  // default: render seeds 7-38 (1920 images, where it was chosen), 30 against 0: found 0.4-0.7
  // visible 221 -> 225, < 0.4 19 -> 20, >= 0.7 5777 -> 5778, false detections 68 -> 68 (the same with
  // no limit; 10 found two fewer); held out, seeds 39-71: 205 -> 206, 17 -> 19, 5808 -> 5809, false
  // 100 -> 102 (both wrong models at blocks missed either way); the support-plane stage about 0.25 ms
  // longer per image (docs/benchmarks.md, session 45). Ten blocks did not seem worth two false ones.
  int support_contour_reserve = 0;
  // In a cluttered image (support_corner_ridge_min_corners image corners or more), an image corner
  // one of whose arms is a thin line (LineRidgeShare(arm, support_corner_ridge_grey) >=
  // support_corner_ridge_share; 0: off) proposes nothing: wood grain meeting a block's edge, or two
  // grain lines, make corners that are no block's vertex, and their placements took the stage's time
  // and, past the cap above, the fitted hypotheses' places. Render seeds 7-71 (3900 images), on
  // against off: found >= 0.7 visible 11602 -> 11579 of 12181, 0.4-0.7 379 -> 394 of 981, < 0.4
  // 29 -> 34, false 176 -> 171; the mean time per image 23.1 -> 19.3 ms, the slowest of 360 47.4 ->
  // 42.0 ms (seeds 7-12, one process); the POV-Ray dev set (at most 114 corners) unchanged. Chosen on
  // seeds 7-38; held out 39-71: found -7 / +7 / +2, false -4. A block's face seen edge-on is a thin
  // strip too: 23 of the 48 blocks lost are slabs and plates (docs/benchmarks.md, session 44).
  // support_corner_ridge_grey: grey levels (smoothed image) by which a thin line stands out from both
  // sides; support_corner_ridge_min_corners: the clutter at which the filter acts (the dev set's
  // images have 39-114 corners, the renders' 55-903).
  double support_corner_ridge_share = 0.5;
  double support_corner_ridge_grey = 8;
  int support_corner_ridge_min_corners = 150;
  double support_min_score = 0.5;            // edge support of a support hypothesis before fitting, 0..1
  double support_perpendicular_tol_deg = 8;  // two horizontal arms on the plane must be this close to 90 deg
  double support_vertical_tol_deg = 4;       // an arm this close to the image vertical may be the vertical edge
  bool support_refine_6dof = true;           // after the fit on the plane, a 6-DOF fit kept when it explains more edges
  // A support hypothesis whose fit (matching within 3 match distances first) ended more than this far
  // from its start (MeanVertexShiftPx) is fitted a second time matching within one match distance
  // from the start, and that pose is verified too when it ends more than 1.5 px from the first. A
  // block half hidden beside another block's or the occluder's edges: the loose first round takes
  // those lines for its hidden edges' and the fit leaves the block for a pose that explains more line
  // length. 0: no second fit. Session 58, chosen on seeds 7-38 from 2, 4 and 6 px: 4 gave 5790 / 275
  // / 28, 76 -> 5794 / 280 / 28, 77 (>= 0.7 / 0.4-0.7 / < 0.4 visible found, false detections); held
  // out, seeds 39-71: 5822 / 249 / 36, 110 -> 5822 / 254 / 37, 110 (docs/benchmarks.md). The same
  // second fit for index hypotheses (from the group's own fit) found nothing more on seeds 7-38.
  double support_tight_fit_shift_px = 4;
  // Other models at a candidate's place (AlternativeHypotheses): for each pose that passed verification
  // and rests on a plane, the other models laid from its bottom corners along its horizontal edges,
  // best edge support first, and this many of them fitted and verified, so that where a wrong model
  // was fitted onto a block (a cube on one end of a bar, a plate on a slab) the right one competes
  // in the selection. Benchmark renders, seeds 7-19: 2287 -> 2294 of 2476 blocks found, false
  // detections 42 -> 35 in 780 images (10 instead of 2: the same); fresh seeds 20-25: 1093 -> 1096
  // of 1181, 23 -> 20 in 360. 2 until session 18, when each model got two places (below). 0: none.
  int max_alternative_fits = 5;
  // Places per model among a candidate's alternatives (distinct: a quarter of the model's smallest
  // side or 10 deg apart). A wrong model's pose is off, so the anchor at the wrong corner can have
  // more edge support than the right one (a slab standing where a bar is: the bar from the far
  // corner 0.77, from the right one 0.65). 1 until session 18.
  int alternatives_per_model = 2;
  // The support-plane hypotheses at a corner whose two segments a candidate has matched: skipped when
  // that candidate is of the hypothesis' own model (false: of any model, as until session 18; a wrong
  // model accepted first then kept the block's own model from ever being fitted there).
  bool skip_corners_claimed_by_any_model = false;
  // --- pose (item 4)
  int max_iterations = 20;                   // Gauss-Newton iterations of Lowe's fit
  double huber_px = 1.5;                     // Huber threshold on line residuals, px
  double match_distance_px = 6;              // a predicted edge matches a segment this close, px
  double match_angle_deg = 8;                // ... and this parallel, deg
  bool polish_pose = true;                   // an accepted pose fitted again on the edge points along its outline (PolishPose)
  // --- verification (item 5)
  double min_matched_edge_fraction = 0.35;   // of the visible predicted edge length matched by image lines, 0..1
  // The rule on the matched share (min_matched_edge_fraction) takes the share of the visible edges'
  // length inside the image, for a pose with at least matched_share_min_in_image of its visible
  // outline there (VisibleOutlineInImage, MatchedWithinImage). Until session 19 it took the whole
  // visible edges, and a block cut by the image border lost its matched share to the part the image
  // cannot show. A pose mostly outside the image is still judged on its whole edges: a wrong model
  // reaching past the border is unconstrained there. The evidence score keeps the whole edges' share.
  // Against the whole edges (session 18), render seeds 7-11 found / false: from any share +4 / +3;
  // from 0.75 +2 / 0; and with the evidence on the in-image share too, from any share +4 / +11, from
  // 0.6 +4 / +2, from 0.75 +2 / 0 but on seeds 12-31 +1 / +7 (this rule: +2 / 0).
  bool matched_share_in_image = true;
  double matched_share_min_in_image = 0.75;
  // A pose short of that matched share is still judged on its evidence, and accepted when it passes
  // the step rule with an evidence score (EvidenceScore) of at least matched_share_rescue_score: the
  // lines along a faint edge (a lit face against the lit table) or a wood-grained face break up into
  // pieces under min_segment_length_px, while the edge points are there. Chosen on render seeds 7-18
  // (found >= 0.7 visible / 0.4-0.7 / false, against 2181 / 48 / 18): 0.95 2185 / 48 / 18, 0.9
  // 2186 / 49 / 18, 0.8 2189 / 49 / 21. At 0.9 on seeds 19-31 2337 -> 2339, 71 -> 72, 31 -> 32 false;
  // fresh seeds 32-41 1789 -> 1791, 47 -> 49, 26 -> 27; the dev set 3 -> 4 of 6 half hidden, still no
  // false detection (docs/benchmarks.md, session 27). Off: every such pose is turned down unjudged.
  bool matched_share_rescue = true;
  double matched_share_rescue_score = 0.9;
  // Blocks partly hidden by recognized ones: after the selection, a pose that verification turned
  // down is judged again with the outline that the accepted recognitions hide left out (a ray from
  // the camera to the outline point passes through an accepted box) and the image lines that they
  // claim left unmatched, when they hide at least occlusion_min_hidden_share of its outline inside
  // the image and leave at least occlusion_min_shown_share of it in view. It joins the accepted ones
  // when it passes, with an evidence score of at least occlusion_min_evidence_score, and conflicts
  // with none of them. Render seeds 7-31 against session 19: +9 found, no false detection more (at a
  // score of 0.9: +11 and +2); fresh seeds 32-41: +3 and none (0.9: +4 and +1).
  bool occlusion_reverify = true;
  double occlusion_min_hidden_share = 0.1;
  double occlusion_min_shown_share = 0.4;
  double occlusion_min_evidence_score = 0.98;
  // Blocks partly hidden by something the library does not hold (an arm, a hand, a tool; the
  // benchmark's dark cylinder): occluding contours, image lines of at least contour_min_length_px
  // (collinear pieces joined) with a median grey-level step of at least contour_min_step_grey across
  // them (OccludingContours). Where one runs across a pose's whole image, past its outline at both
  // ends and along none of its own edges, the outline on one side of it may be hidden; between two
  // nearly parallel ones, the strip between them (ContourOcclusions). The hidden outline must show
  // little edge support (at most contour_max_hidden_coverage of its samples), at least
  // occlusion_min_hidden_share of it hidden and contour_min_shown_share in view. Two uses: the
  // support-plane source scores a placement short of support_min_score again on the outline in view
  // (ranked by that score times the share in view among the others; its fit is judged only as
  // hidden so), and the occlusion pass judges each pose verification turned down again on it, as above. A
  // pose so accepted must not go on past the occluder (an edge into the hidden part, continued over
  // its length beyond its end, finds no step edge along 20 px: a cube fitted to one end of a bar
  // whose middle is hidden), and its model must be the only one the part in view allows (no end face
  // wholly hidden where another model with the same two other sides would end hidden too).
  // Render seeds 7-30 (1440 images, where it was chosen), against none: found >= 0.7 visible 4351 ->
  // 4361, 0.4-0.7 114 -> 132, < 0.4 4 -> 8, false detections 46 -> 48; held out, seeds 31-71: 7229 ->
  // 7236, 186 -> 213, 8 -> 13, 130 -> 131; about a sixth more time per image (docs/benchmarks.md,
  // session 36).
  bool occlusion_contours = true;
  // The occlusion pass also takes the strip between two flanks that end inside the pose's image, or
  // one that does with one beside it (a pole whose top is in front of the block; ContourOcclusions):
  // their ends alike, the same side of the grey-level step towards the strip at both. Render seeds
  // 7-71 (3900 images): found 0.4-0.7 visible 345 -> 359, < 0.4 21 -> 22, >= 0.7 11598 -> 11602,
  // false detections 179 -> 181 (docs/benchmarks.md, session 38).
  bool contour_pole_ends = true;
  // In the occlusion pass, such a strip goes on past the flanks' ends by half its width: a round
  // pole's top (an ellipse from where its flanks end, reaching at most its radius beyond) hides that
  // much more. Render seeds 7-38 (chosen on), against off: found 6096 -> 6102 (7 gained, 1 lost),
  // false detections 68 -> 69; held out, seeds 39-71: 6110 -> 6116 (7 gained, 1 lost), 100 -> 101.
  // 0.35 of its width instead: one block fewer and one false detection fewer in all
  // (docs/benchmarks.md, session 47). Not used by the support-plane source (not measured there).
  bool contour_pole_tops = true;
  // The occlusion pass also takes the strip between a contour across the pose's image and one beside
  // it (the far flank of a pole that hides the block's far part; ContourOcclusions). It hides no more
  // than the near flank's side alone, but bounds it: a longer model laid from the end in view would
  // show its far end past the far flank, so the shorter one is no longer left open (AmbiguousExtent).
  // Render seeds 7-38 (1920 images, where it was chosen): found 0.4-0.7 visible 205 -> 221, < 0.4
  // 17 -> 18, >= 0.7 5772 -> 5777, false detections 70 -> 68; held out, seeds 39-71: 189 -> 205, 17 -> 17,
  // 5807 -> 5808, 101 -> 100. 39 blocks gained (35 cubes, 4 bars), none lost; about 0.1 ms more per image
  // (docs/benchmarks.md, session 45). Not in the support-plane source: there, no block changed.
  bool contour_across_beside = true;
  // The support-plane source takes them too (with contour_pole_ends): a placement short of
  // support_min_score is scored again on the outline beside such flanks. On against off, render seeds
  // 7-71 (3900 images): found 0.4-0.7 visible 458 -> 496 (46.7 -> 50.6 %), < 0.4 39 -> 46, >= 0.7
  // 11608 -> 11611, false detections 177 -> 182 (session 53; session 42 measured 379 -> 392 on the
  // recognizer of then and left it off for 3.5 ms more per image). Time: see docs/benchmarks.md,
  // session 53.
  bool support_pole_ends = true;
  // A contour across a pose's image hides no side with another contour across beyond it, within 30
  // deg of parallel and neither meeting the other's line (ContourPairing::sides_bounded): the near flank of a
  // pole does not hide the outline past its far flank, which is in view; the strip between them still hides
  // what lies between. In both the occlusion pass and the support-plane source. Render seeds 7-71 (3900
  // images), against off: one false detection fewer (185 -> 184), every found block the same; the dev set
  // unchanged (docs/benchmarks.md, session 54).
  bool contour_sides_bounded = true;
  // The support-plane source also takes corners hidden behind an occluding contour
  // (FindHiddenCorners): two edges that run into contours and whose lines meet beyond them. Render
  // seeds 7-22 (960 images, where it was made), against off: found 0.4-0.7 visible 126 -> 127, the
  // rest and the false detections the same; held out, seeds 23-71: 0.4-0.7 411 -> 414, < 0.4 51 -> 52,
  // >= 0.7 the same, false detections 153 -> 151 (docs/benchmarks.md, session 67).
  bool support_hidden_corners = true;
  double hidden_corner_reach_px = 4;      // an edge's end this close to the contour it runs into, px
  double hidden_corner_max_gap_px = 120;  // the corner at most this far beyond each edge's end, px
  double contour_min_length_px = 60;
  double contour_min_step_grey = 30;
  double contour_max_hidden_coverage = 0.3;
  double contour_min_shown_share = 0.5;
  // More than half hidden behind a contour: a pose with less of its outline in view than
  // contour_min_shown_share, but at least contour_low_shown_share, is a placement of the support-plane
  // source and is accepted by the occlusion pass only with an evidence score of at least
  // contour_low_shown_score (where the true and the wrong extents of a block cut by the occluder are
  // hard to tell apart; session 41 chose 0.996, when the wrong ones it traced scored 0.986-0.995 and
  // the true ones mostly 0.997 or more on render seeds 7-38, docs/benchmarks.md; session 57 found the
  // true ones it turned down scoring 0.95-0.995 and lowered it, below). contour_low_shown_share >=
  // contour_min_shown_share turns it off. 0.35 since session 54 (0.4 before): render seeds 7-38
  // (tried first), found 0.4-0.7 visible 260 -> 267, < 0.4 21 -> 25, >= 0.7 and false detections
  // unchanged (5790, 75); held out, seeds 39-71: 236 -> 241, 25 -> 28, 5821, false 107 -> 110 (all
  // three a longer model laid from the part in view of a block cut by the pole or the image border;
  // one of them displaced a cube found at 0.4); the dev set unchanged.
  // contour_low_shown_score 0.985 since session 57 (0.996 before): render seeds 7-38 (chosen on, of
  // 0.93, 0.97 and 0.985), found 0.4-0.7 visible 268 -> 275, < 0.4 25 -> 28, false detections 74 -> 76;
  // held out, seeds 39-71: 241 -> 249, 28 -> 36, false 107 -> 110; no block lost, >= 0.7 visible and
  // unoccluded unchanged. A trade: 26 blocks more for 5 false detections more.
  double contour_low_shown_share = 0.35;
  double contour_low_shown_score = 0.985;
  // Behind an occluding contour, a pose whose hidden outline shows (almost) no edge (at most
  // contour_bare_max_coverage of its samples supported, 0 included: it lies on a uniform occluder, as
  // on the benchmark's dark cylinder) is accepted by the occlusion pass with an evidence score of at
  // least contour_bare_min_evidence_score instead of occlusion_min_evidence_score, when that is the
  // lower (ContourMinEvidenceScore; contour_bare_min_evidence_score >= occlusion_min_evidence_score,
  // e.g. 1, turns it off). Less than contour_min_shown_share in view still needs
  // contour_low_shown_score. Of the 79 blocks 0.4-0.7 visible that verification turned down at their
  // pose on render seeds 7-38, 33 had such a contour and failed only the score (0.93-0.98).
  // Render seeds 7-38 (chosen on), against off: found >= 0.7 visible 5778 -> 5786, 0.4-0.7 226 ->
  // 240, < 0.4 18 -> 19, false detections 69 -> 73; held out, seeds 39-71: 5808 -> 5817, 210 -> 217,
  // 18 -> 20, 101 -> 104; no block lost (0.95: +12 found, +2 false on seeds 7-38; docs/benchmarks.md,
  // session 48). Every new false detection is another model at a partly hidden block. Up to 0.1
  // (session 52, from 0.02): seeds 7-38 found 5786 -> 5789, 240 -> 241, 19, false detections 73
  // (unchanged); held out, seeds 39-71: 5817 -> 5819, 217, 20, 104 (unchanged); 0.3 gave +3, +3, +0
  // and one more false detection on seeds 7-38.
  double contour_bare_max_coverage = 0.1;
  double contour_bare_min_evidence_score = 0.93;
  double min_score = 0.7;                    // edge support where the image shows contrast across the predicted edge, 0..1
  double min_coverage = 0.35;                // edge support along all visible predicted edges, 0..1
  double min_edge_contrast = 25;             // grey levels across a predicted edge (5 px apart) for it to count as informative
                                             // (chosen when canny_low was 40: at 10, true poses failed min_score on edges Canny
                                             // could not detect; with canny_low 16, 15 and 35 found as many as 25, +-3 of 567)
  // A step, not a thin line: of the supported outline, this share must have min_step_grey grey levels
  // (smoothed image) between step_offset_px either side of the predicted edge. Wood grain inside a
  // face gives edges but no step; a wrong model laid onto a block along a grain line is rejected.
  // (Measured on the benchmark's candidates, seeds 7-15: below 0.7 were 1 of 1808 true poses and 212
  // of 555 false ones.) 0 switches the rule off.
  double min_step_share = 0.7;
  double step_offset_px = 4.5;
  double min_step_grey = 12;
  double max_reprojection_rms_px = 1.0;      // matched segments' RMS distance to predicted edges, px (above 1 px the
                                             // dev set's recognitions were the right block but up to 2 deg off)
  // The edge-point refit, a second chance for a pose rejected with its matched lines farther from its
  // predicted edges than max_reprojection_rms_px (a grain line or shadow beside an edge was matched, or
  // the edge's own line was broken up): when its outline is otherwise supported (edge support >=
  // min_score, coverage >= refit_min_coverage) and its evidence score could reach refit_accept_score
  // with no residual at all, it is fitted again in 6 DOF on the image's edge points along its outline
  // (RefitOnEdgePoints). A refitted box with at least refit_min_in_image of its visible outline inside
  // the image (VisibleOutlineInImage: a block cut far by the image border shows too little of it), that
  // rests on the table and whose edge points lie within refit_max_rms_px of its edges is judged again
  // with that RMS and accepted when it passes the rules (the step rule among them) and scores >=
  // refit_accept_score (the selection ranks it by its score with its lines' RMS, as any other pose).
  // Benchmark renders, seeds 7-25: 3390 -> 3425 of 3657 blocks found, false detections 55 -> 57 in 1140
  // images; fresh seeds 26-31: 996 -> 1005 of 1081, 26 -> 26 in 360 (docs/benchmarks.md).
  // refit_accept_score 0.9 -> 0.8 (session 14, chosen on seeds 7-12): seeds 13-31 3372 -> 3383 of 3610
  // found, 70 -> 79 of 277 half hidden, 67 -> 67 false detections in 1140 images; the dev set
  // unchanged. refit_min_in_image 0.8 instead of every corner in the image (session 15): seeds 7-31
  // 4449 -> 4459 of 4738 found, 98 -> 101 of 372 half hidden, false detections 79 -> 79 in 1500 images
  // (0.5, on seeds 7-30: 3 more found >= 0.7 visible, 4 more false). The step rule judged on the
  // refitted pose only, not also on the line fit's (session 15): 4459 -> 4463, 101 -> 102, 79 -> 79.
  // refit_max_rms_px 0.7 -> 0.8 (session 15): 4463 -> 4468, 102 -> 103, 79 -> 79.
  bool edge_point_refit = true;
  double refit_max_rms_px = 0.8;
  double refit_min_coverage = 0.5;
  double refit_accept_score = 0.8;
  double refit_min_in_image = 0.8;
  // The evidence score (EvidenceScore, 0..1): a pose that passes the rules above needs min_evidence_score
  // (it drops most of the false poses that the rules let through); one that fails a rule is still
  // accepted at accept_evidence_score (true poses whose matched lines include a shadow or grain line
  // beside an edge). On renders the weights never saw (seeds 9-11), against the rules alone: 438 -> 454
  // of 555 blocks found, false positives 15 -> 14 in 180 images (docs/benchmarks.md).
  double min_evidence_score = 0.3;
  double accept_evidence_score = 0.8;
  // The selection's pairwise test: a candidate that conflicts with exactly one better-ranked accepted
  // recognition (the same place) replaces it when what it predicts alone is in the image on balance
  // by this many samples (2.5 px apart) or more while what the rival predicts alone is not (3 at most;
  // OwnOutlineBalance, outlines of the other accepted recognitions left out of both). 0: off. On the
  // renders of seeds 20-31, which it was not chosen on: 2110 / 2262 >= 0.7 visible found either way,
  // 0.4-0.7 46 -> 48 of 183, false detections 46 -> 44 in 720 images (docs/benchmarks.md).
  int conflict_balance_margin = 10;
  // The same test's second way to replace the rival, where both own outlines show in the image (a
  // grain line under the wrong model's own edges; ReplacesRival): the candidate's own balance leads
  // the rival's by this many samples and its rank (net edge support times evidence score) is at
  // least conflict_rank_share of the rival's. 0: off. Chosen on the renders of seeds 7-19 from the
  // traced pairwise tests; on seeds 20-31, which it was not chosen on, it added 5 replacements of a
  // wrong rival by the right model and none the other way (docs/benchmarks.md, session 16).
  int conflict_own_lead = 10;
  double conflict_rank_share = 0.8;
  // The rank share asked instead where the rival's box lies within the candidate's (WithinBox) and
  // the rival's image ends at an occluding contour inside the candidate's (EndsAtContourInside): a
  // shorter model fitted onto the part in view of a longer block whose rest something in front
  // hides. The two share that part's outline, and the longer one's rank suffers from its hidden
  // part. Used when lower than conflict_rank_share; 0: off. Session 56, render seeds 7-71: at 0.5,
  // 1 more block found 0.7 or more visible, 1 more 0.4-0.7, 3 false detections fewer, none lost; 0.5
  // without the contour, on seeds 7-38 +3 found and 3 false fewer, but on seeds 39-71 two unoccluded
  // cubes lost to a bar holding them (docs/benchmarks.md).
  double conflict_within_rank_share = 0.5;
  // The same test's third way, where neither own outline shows (both balances under
  // conflict_balance_margin: the image cannot tell the two apart, typically a longer model over a
  // shorter block whose extra length would lie past the image border): the candidate replaces the
  // rival when at least this larger a share of its visible outline lies inside the image
  // (VisibleOutlineInImage; the smaller claim of what cannot be seen) and it ranks at least
  // conflict_tie_rank_share of the rival. 0: off. Chosen from the traced pairwise tests of seeds
  // 7-31: 5 replacements of a wrong rival by the right model, none the other way (docs/benchmarks.md,
  // session 17).
  double conflict_in_image_lead = 0.1;
  double conflict_tie_rank_share = 0.85;
  // The same test's fourth way, where the candidate's own outline shows (its balance reaches
  // conflict_balance_margin) and it is another model: its lines fit it closer than the rival's, their
  // RMS at most conflict_rms_ratio of the rival's, and its evidence score leads the rival's by
  // conflict_score_lead or more. A larger wrong model outranks the right one by its length of outline,
  // shared with the block or lying along its wood grain, but its lines lie off its edges. 0: off.
  // Chosen on render seeds 7-38 from the traced pairwise tests (at 0.5 and 0.03 it turns 6 of the 25
  // that a right candidate lost, on 4 blocks, and none of the 4,196 that a wrong one lost; at 0.7 the
  // same 4 found, one block lost and one false detection more): found 5794 / 280 / 28 ->
  // 5795 / 283 / 28, false detections 77 -> 73; held out, seeds 39-71: 5822 / 254 / 37 -> 5825 / 254
  // / 37, 110 -> 107; no block lost (docs/benchmarks.md, session 59).
  double conflict_rms_ratio = 0.5;
  double conflict_score_lead = 0.03;
  // The same test weighs what each pose claims alone (the part of its image outside the other's and
  // outside every other accepted recognition's, BareTableBeyond): where this share of it or more
  // looks like the bare table (no edge pixel near and the table's grey, TableGrey), that pose's extra
  // length or breadth is not there. A candidate whose own claim is such bare table does not replace its
  // rival; one that would not replace it does when the rival's claim is such bare table and its own at
  // most a third of this share. 0: off. Session 70, render seeds 7-87 against 0 (found >= 0.7 /
  // 0.4-0.7, false detections): 7-22 the same; 39-54, where 0.6 was chosen, +3 / +2, 51 -> 47; held
  // out, 23-38 +1 / +2, 46 -> 43, 55-71 the same, 72-87 +1 / +1, 59 -> 57; the dev set the same. At
  // 0.3 the plain lit faces of five true blocks read as bare table (docs/benchmarks.md).
  double conflict_bare_table_share = 0.6;
  // After the selection and the occlusion pass: a recognition whose claim alone against all the
  // others (BareTableBeyond) is this share or more bare table (10 points at least) is dropped: it
  // stands where the table is bare. 0: off. Session 70: at 0.6, 4 false detections fewer in render
  // seeds 7-87 and no block lost there, but 2 of the dev set's blocks lost (lit faces as grey as the
  // lit table, without grain edges); at 0.8 the dev set keeps them and seeds 39-71 lose 1 false
  // detection. Off (docs/benchmarks.md).
  double max_bare_table_share = 0;
  // Explained away: after the selection, a recognition whose own outline (OwnOutlineBalance against
  // all the other accepted recognitions, fixed edges left out too) shows in the image on balance by
  // fewer than this many samples (2.5 px apart) is dropped, the weakest first: what it predicts the
  // others explain, and the rest of it is not in the image (a plate laid along a cube's top edges, a
  // cube on a bar's end). 0: off. Chosen on the traced selections of render seeds 7-38 (true
  // recognitions' balances 32 and up, 6,000 of them; 1 false one under 30); on seeds 39-71, which it
  // was not chosen on, 6 false recognitions lay under 30 and no true one under 40 (docs/benchmarks.md,
  // session 39).
  int min_own_balance = 30;
  double work_area_radius_m = 0.6;           // poses farther than this from the world origin (in x, y) are culled, m
  double below_table_tolerance_m = 0.010;    // poses whose box reaches deeper under z = 0 are culled, m (a raw
                                             // fit is weakest along the camera ray, and the editor lifts what is
                                             // this close: at 5 mm the benchmark lost 5 true blocks of 567, 1 of 38)
  double support_tolerance_m = 0.012;        // a recognition must rest on something: its lowest point this close to
                                             // the table top, a fixed object's top or another recognition's top, m
  // Off the table a recognition must stand where it rests, not topple: its centre (x, y) within this
  // distance of the region where its footprint overlaps its supports' tops (StandsOnSupports), m.
  // Render seeds 7-31: false detections 73 -> 65 in 1500 images; two blocks no longer counted as
  // found were recognized 35-36 mm off along the camera ray, on a frame wall's edge (session 17).
  double support_centre_slack_m = 0.002;
  // --- model editor (item 6, §4.3)
  double table_snap_distance_m = 0.01;       // an object whose lowest point is this close to a support rests on it, m
  double table_snap_max_tilt_deg = 6;        // ... when one of its faces is this close to horizontal, deg
  // The ladder check (ladder_search_m > 0; off by default): a block resting on the table, moved along
  // either of its sides on the table by ladder_step_m up to ladder_search_m, where a parallel line (a
  // shadow's edge, a grain line, its own thickness) lines up with its outline; the move whose outline
  // shows the most supported step edges (NetSupportPx), fitted there (PolishPose), is taken when it
  // still shows ladder_margin more of them and its evidence score (EvidenceScore) is
  // ladder_score_gain higher. Looked for only when the block's outline is short of edges: coverage
  // (PoseEvidence) under ladder_max_coverage. Measured at 12 mm (docs/benchmarks.md, session 43):
  // render seeds 7-38 (chosen on), found blocks drawn over 5 px off their truth 33 -> 25; seeds 39-71
  // (held out) 27 -> 28, 4 of 14 moves there made the pose worse; +0.8 ms per image. Left off.
  double ladder_search_m = 0;
  double ladder_step_m = 0.002;
  double ladder_margin = 0.1;
  double ladder_score_gain = 0.01;
  double ladder_max_coverage = 0.8;
  [[nodiscard]] Status Validate() const;
  // The least share of a pose's outline in view that any judgement beside an occluding contour
  // takes: contour_low_shown_share, or contour_min_shown_share when that is smaller (the rule off).
  double LeastContourShownShare() const { return std::min(contour_min_shown_share, contour_low_shown_share); }
  // The evidence score the occlusion pass asks of a pose behind an occluding contour whose hidden
  // outline has this share of its samples supported: the lower of contour_bare_min_evidence_score and
  // occlusion_min_evidence_score up to contour_bare_max_coverage, occlusion_min_evidence_score above.
  double ContourMinEvidenceScore(double hidden_coverage) const {
    return hidden_coverage <= contour_bare_max_coverage
               ? std::min(occlusion_min_evidence_score, contour_bare_min_evidence_score)
               : occlusion_min_evidence_score;
  }
};

struct Recognition {
  std::string model;                 // Model::name
  geometry::Pose3 world_T_object;    // after the model editor's rules
  geometry::Pose3 raw_world_T_object;  // as fitted
  double score = 0;                  // 0..1, edge support along the visible predicted edges where the image has contrast
  double matched_edge_fraction = 0;  // share of the visible predicted edge length matched by segments, 0..1
  double reprojection_rms_px = 0;    // RMS distance of matched segment points to their predicted edges, px
  // Of the raw pose, in the object frame's perturbation (translation m in world axes, rotation rad
  // as a world-frame rotation vector): order tx ty tz rx ry rz. From the fit's Gauss-Newton
  // normal matrix scaled by the residual variance.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  std::vector<std::string> adjustments;  // what the model editor did, for people
};

struct RecognitionResult {
  std::vector<Recognition> objects;
  std::vector<std::pair<std::string, double>> timing_ms;  // per stage, in order, ms
};

// A line segment found in the image, in undistorted pixel coordinates (an ideal camera with the
// same intrinsics: straight world edges are straight here).
struct ImageLine {
  Eigen::Vector2d a, b;  // px
  double Length() const { return (b - a).norm(); }
};

// Item 1: sub-pixel Canny edges, chains, Ramer splitting, least-squares fits; undistorted pixels.
std::vector<ImageLine> DetectLines(const cv::Mat& image_gray8, const Camera& camera,
                                   const RecognizerOptions& options);

struct RecognizerIndex;  // the model-view index (internal)

// What happened to each hypothesis the recognizer fitted (for measuring which stage loses an
// object; filled only when asked for).
struct RecognitionTrace {
  enum class Outcome : uint8_t {
    kFitFailed,        // fewer than 3 edges matched while fitting, or behind the camera
    kMatchedFraction,  // too little of the visible predicted edge length matched
    kReprojection,     // matched segments too far from the predicted edges
    kSupport,          // too little edge support along the predicted outline
    kEvidence,         // the evidence score too low (EvidenceScore): below min_evidence_score after passing
                       // the rules above, or below accept_evidence_score after failing one of them
    kImplausible,      // outside the work area, under the table or inside a fixed object
    kCandidate,        // passed; then kept or dropped by the selection below
  };
  // The occlusion pass's second look at a pose verification turned down
  // (RecognizerOptions::occlusion_reverify): its judgement nearest to passing over what may hide
  // part of the pose.
  struct SecondLook {
    enum class Verdict : uint8_t {
      kNone,          // not looked at again: it passed verification, was culled there, its fit
                      // failed, or the pass is off
      kOverlaps,      // it interpenetrates an accepted recognition (another fit of a block found)
      kImplausible,   // culled (outside the work area, under the table, inside a fixed object)
      kNothingHides,  // no accepted recognition in front and no occluding contour across it hides
                      // enough of it, leaves enough in view and has little support behind it
      kRules,         // judged on the part in view: too little matched, or `outcome`
      kScore,         // passed the rules there; evidence score under what the pass asks
      kVetoed,        // passed, but less than contour_min_shown_share in view without
                      // contour_low_shown_score, or it runs on past the contour, or another
                      // model laid from the part in view would end hidden too
      kPassed,        // joined the candidates (the selection after the pass decides)
    };
    Verdict verdict = Verdict::kNone;
    bool behind_contour = false;            // hidden by a contour (else by recognitions in front)
    Outcome outcome = Outcome::kFitFailed;  // the verdict on the part in view (kRules and after)
    double hidden = 0;                      // share of the outline hidden
    double score = 0;                       // evidence score on the part in view (kScore and after)
    double min_score = 0;                   // the score the pass asked there
    // The share of the pose's visible outline outside the image (VisibleOutlineInImage): what the
    // image border cuts off, set for every pose the pass looked at again whatever the verdict.
    double outside_image = 0;
    // Nearer to passing than `other`: a later verdict, or the same with a higher score.
    bool NearerThan(const SecondLook& other) const {
      return verdict != other.verdict ? verdict > other.verdict : score > other.score;
    }
  };
  struct Fitted {
    int model = 0;                             // index into the library
    int group_kind = 0;  // GroupKind, kSupportKind or kAlternativeKind (recognition_stages.h)
    geometry::Pose3 initial_camera_T_object;   // the hypothesis' starting pose
    geometry::Pose3 camera_T_object;           // after the fit
    std::vector<geometry::Pose3> rounds;       // after each fitting round
    Outcome outcome = Outcome::kFitFailed;
    bool accepted = false;  // among the final recognitions (also a pose verification turned down
                            // that the occlusion pass accepted: its outcome stays the first verdict)
    SecondLook second_look;  // the occlusion pass's, of a pose verification turned down
  };
  int lines = 0, groups = 0, hypotheses = 0;
  int corners = 0, support_hypotheses = 0;  // the support-plane source's corners and kept hypotheses
  std::vector<Fitted> fitted;
};

class Recognizer {
 public:
  // Builds the model-view index, or loads it from cache_dir when the library and the index options
  // have not changed (cache_dir empty: no cache). The recognizer is const after this.
  [[nodiscard]] static Result<Recognizer> Create(const ModelLibrary& models, const RecognizerOptions& options,
                                                 const std::string& cache_dir);
  // image: 8-bit monochrome as the camera saw it (distorted). fixed_world: the table/frame the
  // model editor's rules use (objects near z = 0 or a fixed object's top rest on it; recognitions
  // inside fixed objects are culled); may be null (then z = 0 is the table).
  [[nodiscard]] Result<RecognitionResult> Recognize(const cv::Mat& image_gray8, const Camera& camera,
                                                    const scene::Scene* fixed_world,
                                                    RecognitionTrace* trace = nullptr) const;

  const ModelLibrary& models() const { return models_; }
  const RecognizerOptions& options() const { return options_; }
  bool loaded_from_cache() const { return loaded_from_cache_; }
  size_t index_size() const;  // index vectors over all models and group kinds

 private:
  ModelLibrary models_;
  RecognizerOptions options_;
  std::shared_ptr<const RecognizerIndex> index_;
  bool loaded_from_cache_ = false;
};

// Poses equal up to the box's symmetry group (rotations by pi about its axes, and pi/2 about an
// axis whose two other sides are equal): the smallest rotation angle between a and b over it, rad.
double SymmetricRotationAngle(const Model& model, const geometry::Pose3& a, const geometry::Pose3& b);

}  // namespace teachsim::vision
