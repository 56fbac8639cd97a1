#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "densemap/io/file_bytes.hpp"
#include "densemap/io/scan_source.hpp"

namespace densemap {
namespace {

struct PcdField {
  std::string name;
  int size = 4;
  char type = 'F';
  int count = 1;
  std::size_t offset = 0;
};

struct PcdHeader {
  std::vector<PcdField> fields;
  std::size_t points = 0;
  std::size_t point_step = 0;
  std::string data;
  Transform viewpoint = Transform::Identity();
  std::size_t data_offset = 0;  // byte where the payload starts
};

Expected<PcdHeader> parseHeader(const std::filesystem::path& file, const std::string& bytes) {
  PcdHeader h;
  std::size_t pos = 0;
  std::vector<std::string> sizes, types, counts;
  std::size_t width = 0, height = 1;
  bool have_points = false;
  while (pos < bytes.size()) {
    const std::size_t eol = bytes.find('\n', pos);
    if (eol == std::string::npos) return fileError(file, "PCD header ends without a DATA line");
    const std::string line = bytes.substr(pos, eol - pos);
    pos = eol + 1;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string key;
    in >> key;
    std::vector<std::string> values;
    for (std::string v; in >> v;) values.push_back(v);
    try {
      if (key == "FIELDS") {
        for (const auto& v : values) h.fields.push_back({v});
      } else if (key == "SIZE") {
        sizes = values;
      } else if (key == "TYPE") {
        types = values;
      } else if (key == "COUNT") {
        counts = values;
      } else if (key == "WIDTH" && !values.empty()) {
        width = std::stoul(values[0]);
      } else if (key == "HEIGHT" && !values.empty()) {
        height = std::stoul(values[0]);
      } else if (key == "POINTS" && !values.empty()) {
        h.points = std::stoul(values[0]);
        have_points = true;
      } else if (key == "VIEWPOINT") {
        if (values.size() != 7) return fileError(file, "VIEWPOINT needs 7 numbers");
        double v[7];
        for (int i = 0; i < 7; ++i) v[i] = std::stod(values[i]);
        h.viewpoint =
            transformFromTranslationQuaternion({v[0], v[1], v[2]}, v[3], v[4], v[5], v[6]);
        if (auto ok = checkRigidPose(h.viewpoint); !ok) {
          return fileError(file, "VIEWPOINT: " + ok.error().message);
        }
      } else if (key == "DATA") {
        h.data = values.empty() ? "" : values[0];
        h.data_offset = pos;
        break;
      }
    } catch (const std::exception&) {
      return fileError(file, "PCD header line '" + line + "' has a malformed number");
    }
  }
  if (h.data.empty()) return fileError(file, "PCD header has no DATA line");
  if (h.fields.empty()) return fileError(file, "PCD header has no FIELDS");
  if (sizes.size() != h.fields.size() || types.size() != h.fields.size()) {
    return fileError(file, "PCD FIELDS, SIZE and TYPE have different lengths");
  }
  if (!have_points) {
    if (height != 0 && width > bytes.size() / height) {
      return fileError(file, "PCD WIDTH x HEIGHT is more points than the file can hold");
    }
    h.points = width * height;
  }
  // Every point takes at least one byte of the file: reject absurd counts before reserving.
  if (h.points > bytes.size()) {
    return fileError(
        file, "PCD claims " + std::to_string(h.points) + " points, more than the file can hold");
  }
  std::size_t offset = 0;
  for (std::size_t i = 0; i < h.fields.size(); ++i) {
    PcdField& f = h.fields[i];
    f.size = std::atoi(sizes[i].c_str());
    f.type = types[i].empty() ? '?' : types[i][0];
    f.count = i < counts.size() ? std::atoi(counts[i].c_str()) : 1;
    if (f.size <= 0 || f.size > 8 || f.count <= 0 || f.count > 65536) {
      return fileError(file, "bad PCD field size or count");
    }
    f.offset = offset;
    offset += static_cast<std::size_t>(f.size) * f.count;
  }
  h.point_step = offset;
  return h;
}

const PcdField* findField(const PcdHeader& h, const std::string& name) {
  const auto it = std::find_if(h.fields.begin(), h.fields.end(),
                               [&](const PcdField& f) { return f.name == name; });
  return it == h.fields.end() ? nullptr : &*it;
}

}  // namespace

Expected<Scan> readPcd(const std::filesystem::path& file) {
  auto bytes = readFileBytes(file);
  if (!bytes) return std::unexpected(bytes.error());
  auto header = parseHeader(file, *bytes);
  if (!header) return std::unexpected(header.error());
  const PcdHeader& h = *header;
  const PcdField* fx = findField(h, "x");
  const PcdField* fy = findField(h, "y");
  const PcdField* fz = findField(h, "z");
  const PcdField* fi = findField(h, "intensity");
  if (fx == nullptr || fy == nullptr || fz == nullptr) return fileError(file, "PCD lacks x y z");
  for (const PcdField* f : {fx, fy, fz}) {
    if (f->type != 'F' || f->size != 4) return fileError(file, "PCD x y z must be float32 (F 4)");
  }
  if (fi != nullptr && (fi->type != 'F' || fi->size != 4)) fi = nullptr;

  Scan scan;
  scan.frame = PointFrame::kWorld;  // la3dm's PCDs: world-frame points, VIEWPOINT = origin
  scan.T_world_sensor = h.viewpoint;
  scan.points.reserve(h.points);
  if (h.data == "binary") {
    const std::size_t have = bytes->size() - h.data_offset;
    if (h.point_step == 0 || h.points > have / h.point_step) {  // no overflowing product
      return fileError(file, "truncated PCD: " + std::to_string(h.points) + " points of " +
                                 std::to_string(h.point_step) + " bytes, file has " +
                                 std::to_string(have));
    }
    const char* base = bytes->data() + h.data_offset;
    auto get = [&](std::size_t i, const PcdField* f) {
      float v;
      std::memcpy(&v, base + i * h.point_step + f->offset, 4);
      return v;
    };
    for (std::size_t i = 0; i < h.points; ++i) {
      scan.points.emplace_back(get(i, fx), get(i, fy), get(i, fz));
      if (fi != nullptr) scan.intensities.push_back(get(i, fi));
    }
  } else if (h.data == "ascii") {
    std::istringstream in(bytes->substr(h.data_offset));
    std::size_t columns = 0;
    for (const auto& f : h.fields) columns += f.count;
    std::vector<double> row(columns);
    auto column_of = [&](const PcdField* f) {  // first column of a field (counts may be > 1)
      std::size_t column = 0;
      for (const auto& g : h.fields) {
        if (&g == f) break;
        column += g.count;
      }
      return column;
    };
    for (std::size_t i = 0; i < h.points; ++i) {
      for (auto& v : row) {
        // strtod, not >>: "nan" and "inf" are numbers here (a sensor's missing returns), which
        // the mapping tools drop; only a missing or malformed field is an error.
        std::string token;
        if (!(in >> token)) {
          return fileError(file, "truncated ASCII PCD: point " + std::to_string(i) + " of " +
                                     std::to_string(h.points) + " is incomplete");
        }
        char* end = nullptr;
        v = std::strtod(token.c_str(), &end);
        if (end == token.c_str() || *end != '\0') {
          return fileError(
              file, "ASCII PCD point " + std::to_string(i) + ": '" + token + "' is not a number");
        }
      }
      scan.points.emplace_back(static_cast<float>(row[column_of(fx)]),
                               static_cast<float>(row[column_of(fy)]),
                               static_cast<float>(row[column_of(fz)]));
      if (fi != nullptr) scan.intensities.push_back(static_cast<float>(row[column_of(fi)]));
    }
  } else {
    return fileError(file, "PCD DATA '" + h.data + "' is not supported (ascii or binary)");
  }
  return scan;
}

}  // namespace densemap
