#include "teachsim/scene/scene.h"

#include <set>

namespace teachsim::scene {

using json::Json;
using json::Reader;

namespace {

constexpr int kMaxPartDepth = 8;

ShapeSpec ReadShapeSpecAt(const Reader& reader, int depth) {
  if (!reader.IsObject()) reader.Fail("must be an object with one of \"box\", \"convex\", \"parts\"");
  reader.RejectUnknownKeys({"box", "convex", "parts"});
  std::vector<std::string> keys = reader.Keys();
  if (keys.size() != 1) reader.Fail("must have exactly one of \"box\", \"convex\", \"parts\"");
  ShapeSpec spec;
  if (auto box = reader.Find("box")) {
    spec.kind = ShapeSpec::Kind::kBox;
    box->ExpectSize(3);
    for (int i = 0; i < 3; ++i) spec.box_size[i] = box->Index(i).NumberGreaterThan(0.0);
  } else if (auto convex = reader.Find("convex")) {
    spec.kind = ShapeSpec::Kind::kConvex;
    convex->RejectUnknownKeys({"vertices"});
    Reader vertices = convex->At("vertices");
    std::size_t n = vertices.Size();
    if (n < 4) vertices.Fail("needs at least 4 vertices, got " + std::to_string(n));
    for (std::size_t i = 0; i < n; ++i) spec.vertices.push_back(vertices.Index(i).Vector3());
    auto hull = geometry::ConvexPolyhedron::Hull(spec.vertices);
    if (!hull.ok()) vertices.Fail(hull.status().message());
  } else {
    spec.kind = ShapeSpec::Kind::kParts;
    if (depth >= kMaxPartDepth) reader.Fail("parts nested deeper than " + std::to_string(kMaxPartDepth));
    Reader parts = reader.At("parts");
    std::size_t n = parts.Size();
    if (n == 0) parts.Fail("must not be empty");
    for (std::size_t i = 0; i < n; ++i) {
      Reader part = parts.Index(i);
      part.RejectUnknownKeys({"shape", "pose"});
      ShapeSpec::Part p;
      p.shape = ReadShapeSpecAt(part.At("shape"), depth + 1);
      p.pose = part.Has("pose") ? geometry::ReadPose(part.At("pose")) : geometry::Pose3::Identity();
      spec.parts.push_back(std::move(p));
    }
  }
  return spec;
}

Status AppendParts(const ShapeSpec& spec, const geometry::Pose3& shape_T_spec,
                   std::vector<geometry::ShapePart>* parts) {
  switch (spec.kind) {
    case ShapeSpec::Kind::kBox: {
      auto box = geometry::ConvexPolyhedron::Box(spec.box_size);
      if (!box.ok()) return box.status();
      parts->push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(box).value()), shape_T_spec});
      return Status::Ok();
    }
    case ShapeSpec::Kind::kConvex: {
      auto hull = geometry::ConvexPolyhedron::Hull(spec.vertices);
      if (!hull.ok()) return hull.status();
      parts->push_back({std::make_shared<const geometry::ConvexPolyhedron>(std::move(hull).value()), shape_T_spec});
      return Status::Ok();
    }
    case ShapeSpec::Kind::kParts:
      for (const ShapeSpec::Part& part : spec.parts) {
        TEACHSIM_RETURN_IF_ERROR(AppendParts(part.shape, shape_T_spec * part.pose, parts));
      }
      return Status::Ok();
  }
  return Status::Internal("unknown shape kind");
}

Scene ReadScene(const Reader& root) {
  root.RejectUnknownKeys({"objects", "cameras", "robot", "comment"});
  Scene scene;
  Reader objects = root.At("objects");
  std::set<std::string> names;
  for (std::size_t i = 0; i < objects.Size(); ++i) {
    Reader o = objects.Index(i);
    o.RejectUnknownKeys({"name", "fixed", "model", "shape", "pose"});
    SceneObject object;
    object.name = o.At("name").NonEmptyString();
    if (!names.insert(object.name).second) o.At("name").Fail("duplicate object name '" + object.name + "'");
    object.fixed = o.At("fixed").Bool();
    if (auto model = o.Find("model")) object.model = model->NonEmptyString();
    object.shape_spec = ReadShapeSpecAt(o.At("shape"), 0);
    auto shape = BuildShape(object.shape_spec);
    if (!shape.ok()) o.At("shape").Fail(shape.status().message());
    object.shape = std::move(shape).value();
    object.world_T_object = geometry::ReadPose(o.At("pose"));
    scene.objects.push_back(std::move(object));
  }
  if (auto cameras = root.Find("cameras")) {
    std::set<std::string> camera_names;
    for (std::size_t i = 0; i < cameras->Size(); ++i) {
      CameraSpec camera = ReadCamera(cameras->Index(i));
      if (!camera_names.insert(camera.name).second) {
        cameras->Index(i).At("name").Fail("duplicate camera name '" + camera.name + "'");
      }
      scene.cameras.push_back(std::move(camera));
    }
  }
  if (auto robot = root.Find("robot")) {
    robot->RejectUnknownKeys({"model", "base"});
    RobotPlacement placement;
    placement.model = robot->At("model").NonEmptyString();
    placement.world_T_base = geometry::ReadPose(robot->At("base"));
    scene.robot = placement;
  }
  return scene;
}

}  // namespace

int Scene::FindObject(const std::string& name) const {
  for (std::size_t i = 0; i < objects.size(); ++i) {
    if (objects[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

int Scene::FindCamera(const std::string& name) const {
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    if (cameras[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

ShapeSpec ReadShapeSpec(const Reader& reader) { return ReadShapeSpecAt(reader, 0); }

Json WriteShapeSpec(const ShapeSpec& spec) {
  switch (spec.kind) {
    case ShapeSpec::Kind::kBox:
      return {{"box", {spec.box_size.x(), spec.box_size.y(), spec.box_size.z()}}};
    case ShapeSpec::Kind::kConvex: {
      Json vertices = Json::array();
      for (const Eigen::Vector3d& v : spec.vertices) vertices.push_back({v.x(), v.y(), v.z()});
      return {{"convex", {{"vertices", vertices}}}};
    }
    case ShapeSpec::Kind::kParts: {
      Json parts = Json::array();
      for (const ShapeSpec::Part& part : spec.parts) {
        parts.push_back({{"shape", WriteShapeSpec(part.shape)}, {"pose", geometry::WritePose(part.pose)}});
      }
      return {{"parts", parts}};
    }
  }
  return Json::object();
}

CameraSpec ReadCamera(const Reader& c) {
  c.RejectUnknownKeys({"name", "width", "height", "fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3",
                       "gamma", "position", "quaternion_wxyz", "convention"});
  CameraSpec camera;
  camera.name = c.Has("name") ? c.At("name").NonEmptyString() : "camera";
  camera.width = static_cast<int>(c.At("width").IntegerInRange(16, 16384));
  camera.height = static_cast<int>(c.At("height").IntegerInRange(16, 16384));
  camera.fx = c.At("fx").NumberGreaterThan(0.0);
  camera.fy = c.At("fy").NumberGreaterThan(0.0);
  camera.cx = c.At("cx").Number();
  camera.cy = c.At("cy").Number();
  camera.k1 = c.At("k1").NumberInRange(-10.0, 10.0);
  camera.k2 = c.At("k2").NumberInRange(-100.0, 100.0);
  camera.p1 = c.At("p1").NumberInRange(-1.0, 1.0);
  camera.p2 = c.At("p2").NumberInRange(-1.0, 1.0);
  camera.k3 = c.At("k3").NumberInRange(-1000.0, 1000.0);
  if (c.Has("gamma"))
    camera.gamma = c.At("gamma").NumberInRange(0.5, 4.0);  // vision::Camera::kMinGamma, kMaxGamma
  // The pose fields sit directly in the camera entry (world_T_camera).
  Json pose{{"position", c.At("position").raw()}, {"quaternion_wxyz", c.At("quaternion_wxyz").raw()}};
  try {
    camera.world_T_camera = geometry::ReadPose(Reader(pose));
  } catch (const json::ParseError& e) {
    c.Fail(e.what());
  }
  return camera;
}

Json WriteCamera(const CameraSpec& camera) {
  Json pose = geometry::WritePose(camera.world_T_camera);
  Json out = {{"name", camera.name},
              {"width", camera.width},
              {"height", camera.height},
              {"fx", camera.fx},
              {"fy", camera.fy},
              {"cx", camera.cx},
              {"cy", camera.cy},
              {"k1", camera.k1},
              {"k2", camera.k2},
              {"p1", camera.p1},
              {"p2", camera.p2},
              {"k3", camera.k3},
              {"position", pose["position"]},
              {"quaternion_wxyz", pose["quaternion_wxyz"]}};
  if (camera.gamma != 1.0) out["gamma"] = camera.gamma;  // a linear camera's files stay as they were
  return out;
}

Result<CameraSpec> LoadCamera(const std::string& path) {
  auto document = json::ReadFile(path);
  if (!document.ok()) return document.status();
  return json::Decode<CameraSpec>(*document, path, [](const Reader& r) { return ReadCamera(r); });
}

SceneObject BoxObject(const std::string& name, bool fixed, const Eigen::Vector3d& size_m,
                      const geometry::Pose3& world_T_object) {
  SceneObject o;
  o.name = name;
  o.fixed = fixed;
  o.shape_spec.kind = ShapeSpec::Kind::kBox;
  o.shape_spec.box_size = size_m;
  auto shape = BuildShape(o.shape_spec);
  TEACHSIM_CHECK_MSG(shape.ok(), "BoxObject: box sides must be > 0");
  o.shape = std::move(shape).value();
  o.world_T_object = world_T_object;
  return o;
}

Result<geometry::Shape> BuildShape(const ShapeSpec& spec) {
  std::vector<geometry::ShapePart> parts;
  TEACHSIM_RETURN_IF_ERROR(AppendParts(spec, geometry::Pose3::Identity(), &parts));
  return geometry::Shape(std::move(parts));
}

Result<Scene> ParseScene(const Json& document, const std::string& name) {
  return json::Decode<Scene>(document, name, [](const Reader& r) { return ReadScene(r); });
}

Result<Scene> LoadScene(const std::string& path) {
  auto document = json::ReadFile(path);
  if (!document.ok()) return document.status();
  return ParseScene(*document, path);
}

Json SceneToJson(const Scene& scene) {
  Json objects = Json::array();
  for (const SceneObject& o : scene.objects) {
    Json entry{{"name", o.name}, {"fixed", o.fixed}};
    if (!o.model.empty()) entry["model"] = o.model;
    entry["shape"] = WriteShapeSpec(o.shape_spec);
    entry["pose"] = geometry::WritePose(o.world_T_object);
    objects.push_back(std::move(entry));
  }
  Json document{{"objects", objects}};
  Json cameras = Json::array();
  for (const CameraSpec& camera : scene.cameras) cameras.push_back(WriteCamera(camera));
  document["cameras"] = cameras;
  if (scene.robot) {
    document["robot"] = {{"model", scene.robot->model}, {"base", geometry::WritePose(scene.robot->world_T_base)}};
  }
  return document;
}

Status SaveScene(const Scene& scene, const std::string& path) {
  return json::WriteJsonFile(path, SceneToJson(scene));
}

}  // namespace teachsim::scene
