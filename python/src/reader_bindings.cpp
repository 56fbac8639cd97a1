// densemap.read_scans: every dataset format densemap reads, ROS 2 bags too, one scan at a time.
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <filesystem>
#include <memory>

#include "bindings.hpp"
#include "densemap/io/scan.hpp"
#include "densemap/io/scan_source.hpp"
#include "densemap/ros2/recording.hpp"

namespace densemap::python {
namespace {

py::array_t<double> poseArray(const Transform& T) {
  py::array_t<double> out({4, 4});
  const Eigen::Matrix4d m = T.matrix();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) out.mutable_at(r, c) = m(r, c);
  }
  return out;
}

/// The scans of a recording, loaded one at a time on request.
class ScanReader {
 public:
  ScanReader(const std::filesystem::path& path, std::size_t first, std::size_t limit) {
    std::unique_ptr<ScanSource> source;
    {
      py::gil_scoped_release release;
      source = valueOrRaise(ros2::openAnyScanSource(path));
    }
    source_ = std::move(source);
    const std::size_t total = source_->size();
    if (first > total) {
      throw DensemapError("first " + std::to_string(first) + " is past the " +
                          std::to_string(total) + " scans of " + source_->describe());
    }
    first_ = first;
    count_ = limit == 0 ? total - first : std::min(limit, total - first);
  }

  [[nodiscard]] std::size_t size() const { return count_; }
  [[nodiscard]] std::string describe() const { return source_->describe(); }
  [[nodiscard]] Scan load(std::ptrdiff_t index) const {
    if (index < 0) index += static_cast<std::ptrdiff_t>(count_);
    if (index < 0 || static_cast<std::size_t>(index) >= count_) {
      throw py::index_error("scan " + std::to_string(index) + " of " + std::to_string(count_));
    }
    py::gil_scoped_release release;
    return valueOrRaise(source_->load(first_ + static_cast<std::size_t>(index)));
  }

 private:
  std::unique_ptr<ScanSource> source_;
  std::size_t first_ = 0, count_ = 0;
};

}  // namespace

void bindReaders(py::module_& m) {
  py::class_<Scan>(m, "Scan", R"doc(
One scan of a recording: its points in the frame it was stored in, the sensor pose and the time.
Unpacks as (points_world, pose, stamp_ns): `for points, pose, stamp in densemap.read_scans(path)`.
)doc")
      .def_property_readonly(
          "points", [](const Scan& s) { return pointsArray(s.points); },
          "float32 (N, 3), in `frame`.")
      .def_property_readonly(
          "frame",
          [](const Scan& s) { return s.frame == PointFrame::kSensor ? "sensor" : "world"; },
          "'sensor' or 'world': the frame the recording stores the points in.")
      .def_property_readonly(
          "points_world", [](const Scan& s) { return pointsArray(s.pointsWorld()); },
          "float32 (N, 3) in the world frame (transformed once, in double, if stored in the "
          "sensor frame; as OctoMap's tools do for their own formats).")
      .def_property_readonly(
          "origin",
          [](const Scan& s) {
            const Point3f o = s.originWorld();
            return py::make_tuple(o.x(), o.y(), o.z());
          },
          "The sensor's position in the world (the rays' origin).")
      .def_property_readonly(
          "pose", [](const Scan& s) { return poseArray(s.T_world_sensor); },
          "float64 (4, 4): world from sensor.")
      .def_property_readonly(
          "stamp_ns", [](const Scan& s) { return s.stamp_ns; },
          "When the scan was taken (ns), where the format records it; else None.")
      .def("__len__", [](const Scan& s) { return s.points.size(); })
      .def("__iter__", [](const Scan& s) {
        const py::object stamp =
            s.stamp_ns ? py::object(py::int_(*s.stamp_ns)) : py::object(py::none());
        return py::iter(
            py::make_tuple(pointsArray(s.pointsWorld()), poseArray(s.T_world_sensor), stamp));
      });

  py::class_<ScanReader>(m, "ScanReader", R"doc(
The scans of a recording (densemap.read_scans), read one at a time when asked for: memory
holds one scan, whatever the recording's length.
)doc")
      .def("__len__", &ScanReader::size)
      .def("__getitem__", &ScanReader::load, py::arg("index"))
      .def_property_readonly("description", &ScanReader::describe, "The format and location.");

  m.def(
      "read_scans",
      [](const std::filesystem::path& path, std::size_t first, std::size_t limit) {
        return ScanReader(path, first, limit);
      },
      py::arg("path"), py::kw_only(), py::arg("first") = 0, py::arg("limit") = 0,
      R"doc(The scans of a recording: a dataset directory (scans/ + poses, clouds_world/, la3dm
.pcd files), an OctoMap .graph or scan.dat(.bz2), or a ROS 2 bag (.mcap, .db3). `first`:
the first scan to read (0-based), `limit`: how many (0: all). Raises densemap.Error for a path
densemap cannot read, with the reason.)doc");
}

}  // namespace densemap::python
