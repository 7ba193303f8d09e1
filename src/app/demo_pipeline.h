// `teachsim demo`: the paper's two demonstrations end to end (issue 9), from the work site's camera
// image to the verified execution. Per seed the work site's world (the truth) differs from the
// scene file: the blocks lie elsewhere and the camera looks from a slightly different pose. The
// stages (DESIGN.md, "One task, end to end"):
//   1 camera image   the work site renders its camera's view of the MuJoCo world (settled);
//   2 recognition    the recognizer finds the blocks; they become the movable part of the
//                    operator's model (fixed table and frame from the scene file); nothing of the
//                    simulator's truth enters the model;
//   3 demonstration  a scripted drag of the recognized workpiece through the task simulator;
//   4 planning       deform, simplify, emit the program (paper §6);
//   5 execution      the program runs on the MuJoCo world, which is the (perturbed) truth;
//   6 verification   the execution monitor's verdicts: every command reached, every contact verified.
// Format of the outputs: docs/formats/demo.md.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "teachsim/plan/planner.h"
#include "teachsim/robot/robot_model.h"
#include "teachsim/scene/scene.h"
#include "teachsim/sim/script.h"
#include "teachsim/vision/camera.h"
#include "teachsim/worksite/execute.h"

namespace teachsim::app {

inline constexpr int kDemoStages = 6;
// Stage names, 1-based in messages: kDemoStageNames[stage - 1].
inline const char* const kDemoStageNames[kDemoStages] = {"camera image", "recognition", "demonstration",
                                                         "planning",     "execution",   "verification"};

struct DemoOptions {
  std::string which = "all";  // cornering, around-corner or all
  std::string scene_path;     // the operator's scene file (the calibrated work site's fixed world)
  std::string out_dir = "demo-out";
  std::uint64_t seed = 0;     // 0: the world as the scene file says (no perturbation)
  std::string cache_dir;      // the recognizer's model-view index cache ("" : none)
  // What a seed changes in the world (uniform draws): block positions in x, y within a disc of this
  // radius, yaw within +-this; the camera's centre within a ball and its orientation by up to an angle.
  double block_shift_m = 0.015;
  double block_yaw_rad = 10.0 * 3.14159265358979323846 / 180.0;
  double block_gap_m = 0.004;  // a moved block stays at least this far from everything else
  double camera_shift_m = 0.02;
  double camera_angle_rad = 2.0 * 3.14159265358979323846 / 180.0;
  bool progress = true;  // one line per stage on stderr
  [[nodiscard]] Status Validate() const;
};

// One recognized block, scored against the simulated truth (for the report only).
struct DemoRecognition {
  std::string name;   // in the operator's model
  std::string model;  // library model
  Eigen::Vector3d box_size_m = Eigen::Vector3d::Zero();
  geometry::Pose3 world_T_object;
  double score = 0, matched_edge_fraction = 0, reprojection_rms_px = 0;
  std::vector<std::string> adjustments;  // the model editor's
  // Against the truth object of the same model nearest to it ("" when none within 50 mm).
  std::string truth_name;
  double position_error_m = -1, rotation_error_rad = -1;
};

struct DemoTruthObject {
  std::string name, model;
  Eigen::Vector3d box_size_m = Eigen::Vector3d::Zero();
  geometry::Pose3 world_T_object;  // settled in the MuJoCo world
  bool recognized = false;
};

struct StageTime {
  std::string name;
  double wall_s = 0;
};

// Everything the world and recognition stages leave for the demonstrations.
struct DemoWorld {
  scene::Scene file_scene;       // as written
  scene::Scene truth_scene;      // the work site's world: perturbed blocks (before settling), the camera
  scene::CameraSpec camera_spec;  // the work site's (calibrated) camera
  std::vector<DemoTruthObject> truth;  // movable objects, settled
  cv::Mat image;                 // CV_8UC1, the camera image
  std::vector<DemoRecognition> recognitions;
  std::vector<std::pair<std::string, double>> recognizer_timing_ms;
  bool recognizer_from_cache = false;
  scene::Scene operator_scene;   // fixed objects from the file + the recognized blocks + camera + robot
  std::vector<StageTime> times;  // camera image, recognition
  int failed_stage = 0;          // 0: fine; else 1 or 2
  std::string message;
};

struct DemoRun {
  std::string name;      // cornering or around-corner
  std::string workpiece;  // in the operator's model
  std::string workpiece_model;
  bool success = false;
  int failed_stage = 0;   // 1..6, 0 when it succeeded
  std::string message;
  std::vector<StageTime> times;  // demonstration, planning, execution, verification
  std::optional<sim::DragScript> script;
  std::optional<sim::WorkpiecePath> path;
  sim::RunSummary sim_summary;
  std::optional<plan::PlanResult> plan;
  std::optional<worksite::ExecuteResult> execution;
  worksite::ExecuteOptions execute_options;
  std::string path_file, program_file, report_file;  // relative to the output folder
};

struct DemoResult {
  DemoOptions options;
  DemoWorld world;
  std::vector<DemoRun> runs;
  double total_s = 0;
  bool success() const;
};

// The seed's world: blocks moved (resting, within the work area, apart from everything else, and
// with `model` given, still graspable by the arm if they were), the camera moved. Seed 0 returns
// the scene unchanged.
scene::Scene PerturbWorld(const scene::Scene& scene, const DemoOptions& options, const robot::RobotModel* model);

// Runs every stage. Errors (bad input: the scene, the robot table, the options) come back as a
// status; a stage that fails is data in the result (failed_stage, message).
[[nodiscard]] Result<DemoResult> RunDemoPipeline(const DemoOptions& options);

// Stage 2 alone (demo_recognize.cc): the recognizer's view of the image, as DemoRecognition with
// only the recognizer's fields filled. The models come from the scene file.
struct RecognitionOutput {
  std::vector<DemoRecognition> objects;
  std::vector<std::pair<std::string, double>> timing_ms;
  bool from_cache = false;
};
[[nodiscard]] Result<RecognitionOutput> RecognizeBlocks(const std::string& models_path, const cv::Mat& image,
                                                        const vision::Camera& camera,
                                                        const scene::Scene& fixed_world,
                                                        const std::string& cache_dir);

// The recognizer's index cache by default: $TEACHSIM_CACHE/recognizer, else ~/.cache/teachsim/recognizer.
std::string DefaultRecognizerCache();

// The report (demo_report.cc): figures, report.html and demo_summary.json in options.out_dir.
[[nodiscard]] Status WriteDemoReport(const DemoResult& result);

// The smallest rotation between two poses of a box under the box's symmetries, rad.
double BoxRotationError(const Eigen::Vector3d& box_size_m, const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);

}  // namespace teachsim::app
