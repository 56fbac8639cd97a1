// The densemap Python module's native part (densemap._densemap); densemap/__init__.py is its
// face.
#include <cstdlib>
#include <string_view>

#include "bindings.hpp"
#include "densemap/cli/allocator.hpp"
#include "densemap/query/cell_state.hpp"

PYBIND11_MODULE(_densemap, m) {
  namespace py = pybind11;
  // The process's malloc keeps scan-sized buffers in its heap (DENSEMAP_MALLOC=default leaves
  // glibc's defaults, which fault every scan's buffers in anew; docs/python.md).
  if (const char* choice = std::getenv("DENSEMAP_MALLOC");
      choice == nullptr || std::string_view(choice) != "default") {
    densemap::cli::keepScanBuffersInHeap(std::size_t{256} << 20);
  }
  m.doc() = "densemap's native part: import densemap instead.";
  m.attr("__version__") = DENSEMAP_VERSION;
  auto error =
      py::register_exception<densemap::python::DensemapError>(m, "Error", PyExc_RuntimeError);
  error.attr("__doc__") =
      "A refusal or failure of densemap itself (bad option, refused scan, file error, server "
      "timeout), with the message the CLI prints for the same cause.";
  using densemap::CellState;
  m.attr("UNKNOWN") = static_cast<int>(CellState::kUnknown);
  m.attr("FREE") = static_cast<int>(CellState::kFree);
  m.attr("OCCUPIED") = static_cast<int>(CellState::kOccupied);
  densemap::python::bindMapper(m);
  densemap::python::bindClient(m);
  densemap::python::bindReaders(m);
}
