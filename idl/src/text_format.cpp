#include "densemap/idl/text_format.hpp"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>

#include <cctype>

namespace densemap {
namespace {

class FirstError final : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    if (first_.empty()) {
      first_ = "line " + std::to_string(line + 1) + ", column " + std::to_string(column + 1) +
               ": " + message;
    }
  }
  void AddWarning(int, google::protobuf::io::ColumnNumber, const std::string&) override {}
  [[nodiscard]] const std::string& first() const { return first_; }

 private:
  std::string first_;
};

}  // namespace

struct TextLocations::Tree {
  google::protobuf::TextFormat::ParseInfoTree info;
  const google::protobuf::Descriptor* descriptor = nullptr;
};

TextLocations::TextLocations() = default;
TextLocations::~TextLocations() = default;
TextLocations::TextLocations(TextLocations&&) noexcept = default;
TextLocations& TextLocations::operator=(TextLocations&&) noexcept = default;

std::string TextLocations::locate(const std::string& path) const {
  if (!tree_ || tree_->descriptor == nullptr) return "";
  const google::protobuf::TextFormat::ParseInfoTree* tree = &tree_->info;
  const google::protobuf::Descriptor* type = tree_->descriptor;
  std::string found;
  std::size_t start = 0;
  while (tree != nullptr && type != nullptr && start <= path.size()) {
    const std::size_t dot = path.find('.', start);
    const std::string name = path.substr(start, dot == std::string::npos ? dot : dot - start);
    const google::protobuf::FieldDescriptor* field = type->FindFieldByName(name);
    if (field == nullptr || field->is_repeated()) break;
    const google::protobuf::TextFormat::ParseLocation where = tree->GetLocation(field, -1);
    if (where.line < 0) break;  // not in the text: the enclosing message is the nearest
    found =
        "line " + std::to_string(where.line + 1) + ", column " + std::to_string(where.column + 1);
    if (dot == std::string::npos) break;
    type = field->message_type();
    tree = type != nullptr ? tree->GetTreeForNested(field, -1) : nullptr;
    start = dot + 1;
  }
  return found;
}

Expected<void> parseTextFormat(const std::string& text, google::protobuf::Message& message) {
  return parseTextFormat(text, message, nullptr);
}

Expected<void> parseTextFormat(const std::string& text, google::protobuf::Message& message,
                               TextLocations* locations) {
  google::protobuf::TextFormat::Parser parser;
  FirstError errors;
  parser.RecordErrorsTo(&errors);
  if (locations != nullptr) {
    locations->tree_ = std::make_unique<TextLocations::Tree>();
    locations->tree_->descriptor = message.GetDescriptor();
    parser.WriteLocationsTo(&locations->tree_->info);
  }
  if (parser.ParseFromString(text, &message)) return {};
  return makeError(errors.first().empty() ? "invalid text format" : errors.first());
}

std::string locatedError(const TextLocations& locations, const std::string& error) {
  std::size_t end = 0;
  while (end < error.size() && (std::islower(static_cast<unsigned char>(error[end])) ||
                                std::isdigit(static_cast<unsigned char>(error[end])) ||
                                error[end] == '_' || error[end] == '.')) {
    ++end;
  }
  const std::string where = locations.locate(error.substr(0, end));
  return where.empty() ? error : where + ": " + error;
}

}  // namespace densemap
