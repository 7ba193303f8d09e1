// The demo's report (issue 9, item 2): figures drawn by demo_plot, report.html (self-contained:
// inline CSS, no scripts, images as PNG files beside it) and demo_summary.json (docs/formats/demo.md).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <variant>

#include "demo_pipeline.h"
#include "demo_plot.h"
#include "teachsim/worksite/render.h"

namespace teachsim::app {

namespace {

const double kRadToDeg = 180.0 / M_PI;

std::string Escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Fmt(const char* format, double v) {
  char text[64];
  std::snprintf(text, sizeof text, format, v);
  return text;
}

Status Write(const std::filesystem::path& dir, const std::string& file, const cv::Mat& image,
             std::vector<std::string>* written) {
  TEACHSIM_RETURN_IF_ERROR(worksite::WritePng((dir / file).string(), image));
  written->push_back(file);
  return Status::Ok();
}

// The 12 edges of a box, sampled so that the lens distortion bends them as the image does.
void DrawBox(cv::Mat& image, const vision::Camera& camera, const Eigen::Vector3d& size_m,
             const geometry::Pose3& world_T_object, cv::Scalar color, int thickness) {
  const Eigen::Vector3d h = size_m / 2;
  auto corner = [&](int i) {
    return Eigen::Vector3d((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  };
  for (int a = 0; a < 8; ++a) {
    for (int bit = 0; bit < 3; ++bit) {
      const int b = a | (1 << bit);
      if (b == a) continue;
      std::vector<cv::Point> points;
      for (int s = 0; s <= 12; ++s) {
        const Eigen::Vector3d p = world_T_object * (corner(a) + (corner(b) - corner(a)) * (s / 12.0));
        if (const auto px = camera.Project(p, 1e-3)) {
          points.emplace_back(static_cast<int>(std::lround(px->x() * 16)), static_cast<int>(std::lround(px->y() * 16)));
        }
      }
      if (points.size() >= 2) {
        std::vector<std::vector<cv::Point>> poly = {points};
        cv::polylines(image, poly, false, color, thickness, cv::LINE_AA, 4);
      }
    }
  }
}

cv::Mat RecognitionFigure(const DemoWorld& w) {
  cv::Mat image;
  cv::cvtColor(w.image, image, cv::COLOR_GRAY2BGR);
  auto camera = vision::Camera::FromSpec(w.camera_spec);
  if (!camera.ok()) return image;
  const cv::Scalar truth_color(60, 60, 230), recognized_color(60, 220, 60);
  for (const DemoTruthObject& t : w.truth) DrawBox(image, *camera, t.box_size_m, t.world_T_object, truth_color, 1);
  for (const DemoRecognition& r : w.recognitions) {
    DrawBox(image, *camera, r.box_size_m, r.world_T_object, recognized_color, 2);
    const auto centre = camera->Project(r.world_T_object.translation + Eigen::Vector3d(0, 0, r.box_size_m.z() / 2));
    if (!centre) continue;
    const std::string label = r.name + " " + Fmt("%.2f", r.score);
    const cv::Point at(static_cast<int>(centre->x()) - 30, static_cast<int>(centre->y()) - 10);
    plot::PutText(image, label, at + cv::Point(1, 1), 0.45, cv::Scalar(0, 0, 0), 2);
    plot::PutText(image, label, at, 0.45, cv::Scalar(120, 255, 255), 1);
  }
  plot::DrawLegend(image, cv::Point(8, 8),
                   {{"recognized (name, score)", recognized_color}, {"simulated truth", truth_color}});
  return image;
}

// The workpiece's shape in the operator's model.
const scene::SceneObject* FindObject(const scene::Scene& scene, const std::string& name) {
  const int i = scene.FindObject(name);
  return i < 0 ? nullptr : &scene.objects[static_cast<std::size_t>(i)];
}

std::vector<geometry::Pose3> Poses(const sim::WorkpiecePath& path) {
  std::vector<geometry::Pose3> poses;
  for (const sim::PathNode& n : path.nodes) poses.push_back(n.world_T_workpiece);
  return poses;
}

// Figure 12: the model with the initial, deformed and simplified paths as half-size ghost blocks.
cv::Mat ModelViewFigure(const DemoWorld& w, const DemoRun& run) {
  const vision::Camera camera = plot::LookAtCamera(Eigen::Vector3d(0.30, -0.46, 0.36), Eigen::Vector3d(0.03, -0.05, 0.0),
                                                   560, 430, 700);
  const scene::SceneObject* workpiece = FindObject(w.operator_scene, run.workpiece);
  std::vector<plot::Solid> base;
  for (const scene::SceneObject& o : w.operator_scene.objects) {
    if (workpiece != nullptr && o.name == workpiece->name) continue;
    plot::Solid s{o.shape.parts(), o.world_T_object, 1.0, cv::Scalar(95, 150, 195), 1.0, false};
    if (o.fixed && o.name == "table") s.color = cv::Scalar(215, 225, 232), s.background = true;
    if (o.fixed && o.name != "table") s.color = cv::Scalar(70, 120, 165);
    base.push_back(s);
  }
  struct Panel {
    std::string title;
    const sim::WorkpiecePath* path;
    cv::Scalar color;
  };
  std::vector<Panel> panels;
  if (run.plan) {
    panels = {{"(a) demonstrated path", &run.plan->initial, cv::Scalar(250, 250, 250)},
              {"(b) deformed path", &run.plan->deformed, cv::Scalar(240, 200, 150)},
              {"(c) simplified path: the program's knots", &run.plan->simplified, cv::Scalar(60, 160, 250)}};
  } else if (run.path) {
    panels = {{"(a) demonstrated path", &*run.path, cv::Scalar(250, 250, 250)}};
  }
  std::vector<cv::Mat> images;
  for (const Panel& panel : panels) {
    std::vector<plot::Solid> solids = base;
    std::vector<plot::Polyline3> lines;
    const std::vector<geometry::Pose3> poses = Poses(*panel.path);
    if (workpiece != nullptr && !poses.empty()) {
      // The shadow block where the workpiece was, the workpiece where it ends.
      solids.push_back({workpiece->shape.parts(), poses.front(), 1.0, cv::Scalar(140, 140, 140), 0.55, false});
      solids.push_back({workpiece->shape.parts(), poses.back(), 1.0, cv::Scalar(180, 110, 40), 0.85, false});
      // Ghosts at least 15 mm or 10 deg apart along the path (every knot of the simplified one).
      const bool knots = run.plan && panel.path == &run.plan->simplified;
      for (std::size_t i = 0, last = 0; i < poses.size(); ++i) {
        const bool apart = geometry::TranslationDistance(poses[i], poses[last]) > 0.015 ||
                           geometry::RotationAngle(poses[i], poses[last]) > 10 * M_PI / 180;
        if (i == 0 || i + 1 == poses.size() || knots || apart) {
          solids.push_back({workpiece->shape.parts(), poses[i], 0.5, panel.color, 0.9, false});
          last = i;
        }
      }
      plot::Polyline3 centre{{}, cv::Scalar(40, 40, 40), 1, knots};
      for (const geometry::Pose3& p : poses) centre.points_in_world.push_back(p.translation);
      lines.push_back(centre);
    }
    cv::Mat view = plot::DrawModelView(camera, solids, lines, panel.title);
    const std::string count = std::to_string(poses.size()) + " nodes, " +
                              Fmt("%.0f mm", plan::PathLength(poses) * 1e3);
    plot::PutText(view, count, cv::Point(10, view.rows - 12), 0.45, cv::Scalar(0, 0, 0));
    images.push_back(view);
  }
  if (images.empty()) return {};
  // The key in a strip under the panels.
  std::vector<std::pair<std::string, cv::Scalar>> key = {{"shadow block: the start", cv::Scalar(140, 140, 140)},
                                                         {"the workpiece at the end", cv::Scalar(180, 110, 40)}};
  for (const Panel& panel : panels) key.emplace_back("ghosts " + panel.title.substr(0, 3), panel.color);
  cv::Mat all = plot::HConcat(images);
  cv::Mat strip(30, all.cols, CV_8UC3, cv::Scalar(255, 255, 255));
  int x = 12;
  for (const auto& [text, color] : key) {
    cv::rectangle(strip, cv::Rect(x, 8, 22, 14), color, cv::FILLED);
    cv::rectangle(strip, cv::Rect(x, 8, 22, 14), cv::Scalar(60, 60, 60), 1);
    plot::PutText(strip, text, cv::Point(x + 30, 20), 0.45, cv::Scalar(0, 0, 0));
    int baseline = 0;
    x += 30 + cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &baseline).width + 28;
  }
  plot::PutText(strip, "half-size ghost blocks at the path's nodes (15 mm apart; every knot in (c))", cv::Point(x, 20),
                0.45, cv::Scalar(90, 90, 90));
  return plot::VConcat({all, strip});
}

// Force along each contact normal over time, per contact command, with its threshold.
cv::Mat ForcesFigure(const DemoRun& run) {
  if (!run.execution) return {};
  std::vector<cv::Mat> plots;
  const robot::ExecutionReport& report = run.execution->report;
  for (std::size_t i = 0; i < report.commands.size(); ++i) {
    const robot::CommandReport& c = report.commands[i];
    if (c.contacts.empty() || c.forces.empty()) continue;
    plot::LineChart chart;
    int verified = 0;
    for (const robot::ContactCheck& k : c.contacts) verified += k.verified ? 1 : 0;
    chart.title = "commands[" + std::to_string(i) + "] " + c.type + ": " + robot::CommandStatusName(c.status) + ", " +
                  std::to_string(verified) + "/" + std::to_string(c.contacts.size()) + " contacts verified";
    chart.x_label = "time since the command started, s";
    chart.y_label = "along the normal, N";
    for (std::size_t k = 0; k < c.contacts.size(); ++k) {
      const Eigen::Vector3d& n = c.contacts[k].normal;
      plot::Line line;
      char label[96];
      std::snprintf(label, sizeof label, "n%zu (%.2f, %.2f, %.2f)%s", k, n.x(), n.y(), n.z(),
                    c.contacts[k].verified ? "" : " NOT verified");
      line.label = label;
      line.color = plot::Palette(static_cast<int>(k));
      for (const robot::ForceSample& s : c.forces) {
        line.x.push_back(s.t_s - c.start_s);
        line.y.push_back(s.force_n.dot(n));
      }
      plot::Line threshold;
      threshold.color = line.color;
      threshold.dashed = true;
      threshold.thickness = 1;
      threshold.x = {0.0, std::max(c.end_s - c.start_s, 1e-3)};
      threshold.y = {c.contacts[k].threshold_n, c.contacts[k].threshold_n};
      chart.lines.push_back(line);
      chart.lines.push_back(threshold);
    }
    plot::Line dashed_key;
    dashed_key.label = "thresholds (dashed)";
    dashed_key.color = cv::Scalar(90, 90, 90);
    chart.lines.push_back(dashed_key);
    plots.push_back(plot::DrawLineChart(chart, 640, 290));
  }
  if (plots.empty()) return {};
  std::vector<cv::Mat> rows;
  for (std::size_t i = 0; i < plots.size(); i += 2) {
    rows.push_back(i + 1 < plots.size() ? plot::HConcat({plots[i], plots[i + 1]}) : plots[i]);
  }
  return plot::VConcat(rows);
}

cv::Mat RecognitionErrorsFigure(const DemoWorld& w) {
  plot::BarChart position, rotation;
  position.title = "recognition: position error vs the simulated truth";
  position.y_label = "mm";
  rotation.title = "recognition: rotation error (box symmetries)";
  rotation.y_label = "deg";
  position.series = rotation.series = {""};
  position.values.resize(1), rotation.values.resize(1);
  position.colors = {plot::Palette(0)};
  rotation.colors = {plot::Palette(1)};
  rotation.value_format = "%.2f";
  for (const DemoRecognition& r : w.recognitions) {
    position.categories.push_back(r.name);
    rotation.categories.push_back(r.name);
    position.values[0].push_back(r.position_error_m >= 0 ? r.position_error_m * 1e3 : NAN);
    rotation.values[0].push_back(r.rotation_error_rad >= 0 ? r.rotation_error_rad * kRadToDeg : NAN);
  }
  return plot::HConcat({plot::DrawBarChart(position, 520, 300), plot::DrawBarChart(rotation, 520, 300)});
}

cv::Mat PathLengthsFigure(const std::vector<DemoRun>& runs) {
  plot::BarChart chart;
  chart.title = "path length: demonstrated, deformed, simplified (translation)";
  chart.y_label = "mm";
  chart.series = {"demonstrated", "deformed", "simplified"};
  chart.values.assign(3, {});
  chart.value_format = "%.0f";
  for (const DemoRun& r : runs) {
    if (!r.plan) continue;
    chart.categories.push_back(r.name);
    chart.values[0].push_back(plan::PathLength(Poses(r.plan->initial)) * 1e3);
    chart.values[1].push_back(plan::PathLength(Poses(r.plan->deformed)) * 1e3);
    chart.values[2].push_back(plan::PathLength(Poses(r.plan->simplified)) * 1e3);
  }
  return plot::DrawBarChart(chart, 620, 300);
}

cv::Mat TimingsFigure(const DemoResult& result) {
  plot::BarChart stages;
  stages.title = "wall time per stage (stages 1-2 are shared by the demonstrations)";
  stages.y_label = "s";
  stages.value_format = "%.2f";
  for (int s = 0; s < kDemoStages; ++s) stages.categories.push_back(kDemoStageNames[s]);
  for (const DemoRun& r : result.runs) {
    stages.series.push_back(r.name);
    std::vector<double> v(kDemoStages, NAN);
    for (const StageTime& t : result.world.times) {
      for (int s = 0; s < kDemoStages; ++s) {
        if (t.name == kDemoStageNames[s]) v[static_cast<std::size_t>(s)] = t.wall_s;
      }
    }
    for (const StageTime& t : r.times) {
      for (int s = 0; s < kDemoStages; ++s) {
        if (t.name == kDemoStageNames[s]) v[static_cast<std::size_t>(s)] = t.wall_s;
      }
    }
    stages.values.push_back(v);
  }
  cv::Mat left = plot::DrawBarChart(stages, 700, 320);
  if (result.world.recognizer_timing_ms.empty()) return left;
  plot::BarChart recognizer;
  recognizer.title = "recognizer, per step";
  recognizer.y_label = "ms";
  recognizer.series = {""};
  recognizer.values.resize(1);
  recognizer.colors = {plot::Palette(2)};
  recognizer.value_format = "%.0f";
  for (const auto& [name, ms] : result.world.recognizer_timing_ms) {
    recognizer.categories.push_back(name);
    recognizer.values[0].push_back(ms);
  }
  return plot::HConcat({left, plot::DrawBarChart(recognizer, 520, 320)});
}

json::Json PoseJson(const geometry::Pose3& pose) { return geometry::WritePose(pose); }

std::string StageName(int stage) { return stage >= 1 && stage <= kDemoStages ? kDemoStageNames[stage - 1] : ""; }

}  // namespace

Status WriteDemoReport(const DemoResult& result) {
  const std::filesystem::path dir(result.options.out_dir);
  const DemoWorld& w = result.world;
  std::vector<std::string> figures;

  // --- figures
  const bool have_image = !w.image.empty();
  if (have_image) TEACHSIM_RETURN_IF_ERROR(Write(dir, "recognitions.png", RecognitionFigure(w), &figures));
  if (!w.recognitions.empty()) {
    TEACHSIM_RETURN_IF_ERROR(Write(dir, "recognition_errors.png", RecognitionErrorsFigure(w), &figures));
  }
  bool any_plan = false;
  for (const DemoRun& r : result.runs) any_plan = any_plan || r.plan.has_value();
  if (any_plan) TEACHSIM_RETURN_IF_ERROR(Write(dir, "path_lengths.png", PathLengthsFigure(result.runs), &figures));
  TEACHSIM_RETURN_IF_ERROR(Write(dir, "timings.png", TimingsFigure(result), &figures));
  std::map<std::string, std::string> model_views, force_figures;
  for (const DemoRun& r : result.runs) {
    if (const cv::Mat m = ModelViewFigure(w, r); !m.empty()) {
      model_views[r.name] = r.name + ".model.png";
      TEACHSIM_RETURN_IF_ERROR(Write(dir, model_views[r.name], m, &figures));
    }
    if (const cv::Mat f = ForcesFigure(r); !f.empty()) {
      force_figures[r.name] = r.name + ".forces.png";
      TEACHSIM_RETURN_IF_ERROR(Write(dir, force_figures[r.name], f, &figures));
    }
  }

  // --- demo_summary.json
  json::Json summary;
  summary["format"] = "teachsim-demo-summary";
  summary["version"] = 1;
  summary["seed"] = result.options.seed;
  summary["scene"] = result.options.scene_path;
  summary["which"] = result.options.which;
  summary["success"] = result.success();
  summary["total_s"] = result.total_s;
  json::Json world_stages = json::Json::array();
  for (const StageTime& t : w.times) world_stages.push_back({{"name", t.name}, {"wall_s", t.wall_s}});
  summary["world"] = {{"stages", world_stages},
                      {"camera", scene::WriteCamera(w.camera_spec)},
                      {"failed_stage", w.failed_stage},
                      {"message", w.message}};
  json::Json recognitions = json::Json::array(), missed = json::Json::array(), timing = json::Json::object();
  for (const DemoRecognition& r : w.recognitions) {
    json::Json o = {{"name", r.name},
                    {"model", r.model},
                    {"world_T_object", PoseJson(r.world_T_object)},
                    {"score", r.score},
                    {"matched_edge_fraction", r.matched_edge_fraction},
                    {"reprojection_rms_px", r.reprojection_rms_px},
                    {"adjustments", r.adjustments}};
    if (!r.truth_name.empty()) {
      o["truth"] = r.truth_name;
      o["position_error_m"] = r.position_error_m;
      o["rotation_error_deg"] = r.rotation_error_rad * kRadToDeg;
    } else {
      o["truth"] = nullptr;  // a false recognition: no block of its model within 50 mm
    }
    recognitions.push_back(o);
  }
  for (const DemoTruthObject& t : w.truth) {
    if (!t.recognized) missed.push_back(t.name);
  }
  for (const auto& [name, ms] : w.recognizer_timing_ms) timing[name] = ms;
  summary["recognition"] = {{"objects", recognitions},
                            {"missed", missed},
                            {"timing_ms", timing},
                            {"index_from_cache", w.recognizer_from_cache}};
  json::Json demos = json::Json::array();
  for (const DemoRun& r : result.runs) {
    json::Json d = {{"name", r.name},
                    {"workpiece", r.workpiece},
                    {"workpiece_model", r.workpiece_model},
                    {"success", r.success},
                    {"failed_stage", r.failed_stage},
                    {"failed_stage_name", StageName(r.failed_stage)},
                    {"message", r.message}};
    json::Json stages = json::Json::array();
    for (const StageTime& t : r.times) stages.push_back({{"name", t.name}, {"wall_s", t.wall_s}});
    d["stages"] = stages;
    if (r.plan) {
      d["path_length_m"] = {{"demonstrated", plan::PathLength(Poses(r.plan->initial))},
                            {"deformed", plan::PathLength(Poses(r.plan->deformed))},
                            {"simplified", plan::PathLength(Poses(r.plan->simplified))}};
      d["knots"] = r.plan->metrics.knots;
    }
    if (r.execution) {
      json::Json commands = json::Json::array();
      const robot::ExecutionReport& report = r.execution->report;
      for (std::size_t i = 0; i < report.commands.size(); ++i) {
        const robot::CommandReport& c = report.commands[i];
        int verified = 0;
        for (const robot::ContactCheck& k : c.contacts) verified += k.verified ? 1 : 0;
        commands.push_back({{"index", i},
                            {"type", c.type},
                            {"status", robot::CommandStatusName(c.status)},
                            {"contacts", c.contacts.size()},
                            {"contacts_verified", verified},
                            {"peak_force_n", c.peak_force_n},
                            {"message", c.message}});
      }
      d["commands"] = commands;
      d["execution"] = {{"success", r.execution->success},
                        {"message", r.execution->message},
                        {"simulated_s", r.execution->simulated_s},
                        {"peak_force_n", report.peak_force_n},
                        {"workpiece_position_error_m", r.execution->workpiece_position_error_m},
                        {"workpiece_angle_error_deg", r.execution->workpiece_angle_error_rad * kRadToDeg}};
    }
    json::Json files = json::Json::array();
    for (const std::string& f : {r.path_file, r.program_file, r.report_file}) {
      if (!f.empty()) files.push_back(f);
    }
    d["files"] = files;
    demos.push_back(d);
  }
  summary["demos"] = demos;
  summary["figures"] = figures;
  TEACHSIM_RETURN_IF_ERROR(json::WriteJsonFile((dir / "demo_summary.json").string(), summary));

  // --- report.html
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>teachsim demo, seed "
    << result.options.seed << "</title>\n<style>\n"
    << "body{font-family:system-ui,sans-serif;max-width:1400px;margin:1em auto;padding:0 1em;color:#222}\n"
    << "table{border-collapse:collapse;margin:.5em 0 1em}td,th{border:1px solid #bbb;padding:.2em .6em;"
       "text-align:left;font-size:.9em}th{background:#eee}\n"
    << ".ok{color:#1a7f37;font-weight:bold}.bad{color:#c62828;font-weight:bold}\n"
    << "img{max-width:100%;border:1px solid #ddd;margin:.3em 0}figure{margin:1em 0}figcaption{font-size:.9em;"
       "color:#555}\npre{background:#f6f6f6;padding:.5em;overflow-x:auto;font-size:.8em}\n</style></head><body>\n";
  h << "<h1>teachsim demo: " << Escape(result.options.which) << ", seed " << result.options.seed << "</h1>\n";
  h << "<p>Scene <code>" << Escape(result.options.scene_path) << "</code>. Overall: "
    << (result.success() ? "<span class=ok>SUCCESS</span>" : "<span class=bad>FAILED</span>") << " in "
    << Fmt("%.1f", result.total_s) << " s. Machine-readable: <a href=\"demo_summary.json\">demo_summary.json</a>.</p>\n";
  h << "<table><tr><th>demonstration</th><th>verdict</th><th>failed stage</th><th>message</th></tr>\n";
  for (const DemoRun& r : result.runs) {
    h << "<tr><td>" << Escape(r.name) << "</td><td>"
      << (r.success ? "<span class=ok>verified</span>" : "<span class=bad>failed</span>") << "</td><td>"
      << (r.failed_stage ? std::to_string(r.failed_stage) + "/6 " + StageName(r.failed_stage) : "") << "</td><td>"
      << Escape(r.message) << "</td></tr>\n";
  }
  h << "</table>\n";

  h << "<h2>1. The work site's camera image</h2>\n";
  if (have_image) {
    h << "<figure><img src=\"camera.png\" alt=\"camera image\"><figcaption>The simulated camera's image of the "
         "settled MuJoCo world (<a href=\"camera.truth.json\">truth</a>, <a href=\"world.scene.json\">the world's "
         "scene</a>).</figcaption></figure>\n";
  }
  h << "<h2>2. Recognition</h2>\n";
  if (w.failed_stage == 2) h << "<p class=bad>" << Escape(w.message) << "</p>\n";
  if (have_image && !w.recognitions.empty()) {
    h << "<figure><img src=\"recognitions.png\" alt=\"recognitions\"><figcaption>Recognized blocks (green, with "
         "their names in the operator's model and verification scores) and the simulated truth (red). "
         "The operator's model: <a href=\"operator.scene.json\">operator.scene.json</a>.</figcaption></figure>\n";
    h << "<table><tr><th>name</th><th>model</th><th>score</th><th>matched edges</th><th>rms px</th><th>truth</th>"
         "<th>position error mm</th><th>rotation error deg</th><th>model editor</th></tr>\n";
    for (const DemoRecognition& r : w.recognitions) {
      std::string adjust;
      for (const std::string& a : r.adjustments) adjust += (adjust.empty() ? "" : "; ") + a;
      h << "<tr><td>" << Escape(r.name) << "</td><td>" << Escape(r.model) << "</td><td>" << Fmt("%.2f", r.score)
        << "</td><td>" << Fmt("%.2f", r.matched_edge_fraction) << "</td><td>" << Fmt("%.2f", r.reprojection_rms_px)
        << "</td><td>" << (r.truth_name.empty() ? "<span class=bad>none (false)</span>" : Escape(r.truth_name))
        << "</td><td>" << (r.position_error_m >= 0 ? Fmt("%.1f", r.position_error_m * 1e3) : "")
        << "</td><td>" << (r.rotation_error_rad >= 0 ? Fmt("%.2f", r.rotation_error_rad * kRadToDeg) : "")
        << "</td><td>" << Escape(adjust) << "</td></tr>\n";
    }
    h << "</table>\n";
    std::string missed_names;
    for (const DemoTruthObject& t : w.truth) {
      if (!t.recognized) missed_names += (missed_names.empty() ? "" : ", ") + t.name;
    }
    h << "<p>Missed blocks: " << (missed_names.empty() ? "none" : Escape(missed_names)) << ".</p>\n";
    h << "<figure><img src=\"recognition_errors.png\" alt=\"recognition errors\"><figcaption>What vision got wrong "
         "— the difference between the operator's model and the work site's world.</figcaption></figure>\n";
  }

  for (const DemoRun& r : result.runs) {
    h << "<h2>" << Escape(r.name) << ": " << (r.success ? "<span class=ok>verified</span>" : "<span class=bad>failed</span>")
      << "</h2>\n";
    if (!r.success) {
      h << "<p class=bad>Failed at stage " << r.failed_stage << "/6 (" << StageName(r.failed_stage)
        << "): " << Escape(r.message) << "</p>\n";
    }
    if (model_views.count(r.name)) {
      h << "<figure><img src=\"" << model_views[r.name] << "\" alt=\"model view\"><figcaption>As the paper's Figure "
           "12: the operator's model (recognized blocks, the frame and table from the scene file) with the "
           "workpiece path as half-size ghost blocks: (a) as demonstrated, (b) deformed, (c) simplified into the "
           "program's knots.</figcaption></figure>\n";
    }
    if (r.plan) {
      h << "<h3>Program (<a href=\"" << r.program_file << "\">" << r.program_file << "</a>)</h3>\n<pre>"
        << Escape(robot::ProgramListing(r.plan->program)) << "</pre>\n";
    }
    if (r.execution) {
      const robot::ExecutionReport& report = r.execution->report;
      h << "<h3>Execution on the work site (<a href=\"" << r.report_file << "\">" << r.report_file << "</a>)</h3>\n";
      h << "<p>" << Escape(r.execution->message) << "; " << Fmt("%.1f", r.execution->simulated_s)
        << " s simulated; workpiece " << Fmt("%.1f", r.execution->workpiece_position_error_m * 1e3) << " mm / "
        << Fmt("%.1f", r.execution->workpiece_angle_error_rad * kRadToDeg) << " deg from the program's intent.</p>\n";
      h << "<table><tr><th>#</th><th>command</th><th>status</th><th>contacts verified</th><th>peak force N</th>"
           "<th>time s</th><th>message</th></tr>\n";
      for (std::size_t i = 0; i < report.commands.size(); ++i) {
        const robot::CommandReport& c = report.commands[i];
        int verified = 0;
        for (const robot::ContactCheck& k : c.contacts) verified += k.verified ? 1 : 0;
        const bool ok = c.status == robot::CommandStatus::kReached && c.contacts_verified;
        h << "<tr><td>" << i << "</td><td>" << Escape(c.type) << "</td><td class=" << (ok ? "ok" : "bad") << ">"
          << robot::CommandStatusName(c.status) << "</td><td>"
          << (c.contacts.empty() ? std::string("-")
                                 : std::to_string(verified) + "/" + std::to_string(c.contacts.size()))
          << "</td><td>" << Fmt("%.1f", c.peak_force_n) << "</td><td>" << Fmt("%.2f", c.start_s) << " - "
          << Fmt("%.2f", c.end_s) << "</td><td>" << Escape(c.message) << "</td></tr>\n";
      }
      h << "</table>\n";
      if (force_figures.count(r.name)) {
        h << "<figure><img src=\"" << force_figures[r.name] << "\" alt=\"contact forces\"><figcaption>The force on "
             "the tool along each contact normal (from the obstacle toward the workpiece) during each contact "
             "move, and the threshold the monitor checks (dashed).</figcaption></figure>\n";
      }
    }
    if (!r.path_file.empty()) {
      h << "<p>Files: <a href=\"" << r.name << ".drags.json\">drag script</a>, <a href=\"" << r.path_file
        << "\">demonstrated path</a>";
      if (r.plan) {
        h << ", <a href=\"" << r.name << ".initial.path.json\">initial</a>, <a href=\"" << r.name
          << ".deformed.path.json\">deformed</a>, <a href=\"" << r.name << ".simplified.path.json\">simplified</a>";
      }
      h << ".</p>\n";
    }
  }

  h << "<h2>Stages</h2>\n";
  if (any_plan) {
    h << "<figure><img src=\"path_lengths.png\" alt=\"path lengths\"><figcaption>Path length before and after the "
         "program generator.</figcaption></figure>\n";
  }
  h << "<figure><img src=\"timings.png\" alt=\"timings\"><figcaption>Wall time per stage on this machine.</figcaption>"
       "</figure>\n<table><tr><th>stage</th>";
  for (const DemoRun& r : result.runs) h << "<th>" << Escape(r.name) << " s</th>";
  h << "</tr>\n";
  for (int s = 0; s < kDemoStages; ++s) {
    h << "<tr><td>" << s + 1 << " " << kDemoStageNames[s] << "</td>";
    for (const DemoRun& r : result.runs) {
      std::string cell;
      for (const StageTime& t : w.times) {
        if (t.name == kDemoStageNames[s]) cell = Fmt("%.2f", t.wall_s) + " (shared)";
      }
      for (const StageTime& t : r.times) {
        if (t.name == kDemoStageNames[s]) cell = Fmt("%.2f", t.wall_s);
      }
      h << "<td>" << cell << "</td>";
    }
    h << "</tr>\n";
  }
  h << "</table>\n</body></html>\n";
  return json::WriteFileAtomic((dir / "report.html").string(), h.str());
}

}  // namespace teachsim::app
