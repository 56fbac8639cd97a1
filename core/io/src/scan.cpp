#include "densemap/io/scan.hpp"

namespace densemap {

PointCloud Scan::pointsWorld() const {
  return frame == PointFrame::kWorld ? points : transformPoints(T_world_sensor, points);
}

}  // namespace densemap
