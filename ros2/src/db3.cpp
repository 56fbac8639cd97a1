#include "densemap/ros2/db3.hpp"

#include <sqlite3.h>

#include <map>
#include <mutex>

#include "densemap/io/file_bytes.hpp"

namespace densemap::ros2 {
namespace {

/// A prepared statement, finalized with its scope.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) {
    ok_ = sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) == SQLITE_OK;
  }
  ~Statement() { sqlite3_finalize(s_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  [[nodiscard]] bool ok() const { return ok_; }
  [[nodiscard]] sqlite3_stmt* get() const { return s_; }

 private:
  sqlite3_stmt* s_ = nullptr;
  bool ok_ = false;
};

std::string text(sqlite3_stmt* s, int column) {
  const unsigned char* t = sqlite3_column_text(s, column);
  const int n = sqlite3_column_bytes(s, column);
  return t != nullptr ? std::string(reinterpret_cast<const char*>(t), static_cast<std::size_t>(n))
                      : std::string();
}

}  // namespace

struct Db3Reader::Db {
  sqlite3* handle = nullptr;
  mutable std::mutex mutex;
  ~Db() { sqlite3_close(handle); }
};

Db3Reader::Db3Reader() : db_(std::make_unique<Db>()) {}
Db3Reader::~Db3Reader() = default;

Expected<std::unique_ptr<Db3Reader>> Db3Reader::open(const std::filesystem::path& path,
                                                     std::size_t max_messages) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return fileError(path, "not a regular file");
  std::unique_ptr<Db3Reader> r(new Db3Reader());
  r->name_ = path.string();
  sqlite3*& db = r->db_->handle;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    return fileError(path, std::string("cannot open as SQLite: ") + sqlite3_errmsg(db));
  }
  const auto failed = [&](const std::string& what) {
    return fileError(path, "not a rosbag2 SQLite bag (" + what + ": " + sqlite3_errmsg(db) + ")");
  };
  Statement topics(db, "SELECT id, name, type, serialization_format FROM topics ORDER BY id");
  if (!topics.ok()) return failed("its topics");
  std::map<std::int64_t, std::uint16_t> channel_of;
  int rc = SQLITE_ROW;
  while ((rc = sqlite3_step(topics.get())) == SQLITE_ROW) {
    if (r->channels().size() >= 65535) return fileError(path, "more than 65535 topics");
    BagChannel c;
    c.id = static_cast<std::uint16_t>(r->channels().size());
    c.topic = text(topics.get(), 1);
    c.schema_name = text(topics.get(), 2);
    c.message_encoding = text(topics.get(), 3);
    c.schema_encoding = "ros2msg";
    channel_of[sqlite3_column_int64(topics.get(), 0)] = c.id;
    r->addChannel(std::move(c));
  }
  if (rc != SQLITE_DONE) return failed("its topics");
  Statement messages(db,
                     "SELECT id, topic_id, timestamp, length(data) FROM messages "
                     "ORDER BY timestamp, id");
  if (!messages.ok()) return failed("its messages");
  while ((rc = sqlite3_step(messages.get())) == SQLITE_ROW) {
    const auto topic = channel_of.find(sqlite3_column_int64(messages.get(), 1));
    if (topic == channel_of.end()) continue;  // a message of no topic: not ours to read
    if (r->messages_.size() >= max_messages) return fileError(path, "too many messages");
    const std::int64_t time = sqlite3_column_int64(messages.get(), 2);
    r->messages_.push_back({topic->second,
                            static_cast<std::uint64_t>(std::max<std::int64_t>(time, 0)), -1,
                            static_cast<std::uint64_t>(sqlite3_column_int64(messages.get(), 0)),
                            static_cast<std::uint64_t>(sqlite3_column_int64(messages.get(), 3))});
  }
  if (rc != SQLITE_DONE) return failed("its messages");
  return r;
}

Expected<std::string> Db3Reader::data(const BagMessage& m, std::uint64_t max_bytes) const {
  std::lock_guard lock(db_->mutex);
  // A prefix is cut by SQLite (substr of a blob): the rest is never copied out.
  const bool whole = max_bytes >= m.length;
  Statement s(db_->handle, whole ? "SELECT data FROM messages WHERE id = ?"
                                 : "SELECT substr(data, 1, ?2) FROM messages WHERE id = ?1");
  if (!s.ok()) return makeError(name_ + ": " + sqlite3_errmsg(db_->handle));
  sqlite3_bind_int64(s.get(), 1, static_cast<sqlite3_int64>(m.offset));
  if (!whole) sqlite3_bind_int64(s.get(), 2, static_cast<sqlite3_int64>(max_bytes));
  if (sqlite3_step(s.get()) != SQLITE_ROW) {
    return makeError(name_ + ": message " + std::to_string(m.offset) + " is gone (" +
                     sqlite3_errmsg(db_->handle) + ")");
  }
  const void* blob = sqlite3_column_blob(s.get(), 0);
  const int n = sqlite3_column_bytes(s.get(), 0);
  return blob != nullptr ? std::string(static_cast<const char*>(blob), static_cast<std::size_t>(n))
                         : std::string();
}

Expected<void> writeDb3(const std::filesystem::path& path, const std::vector<Db3Topic>& topics,
                        const std::vector<Db3Row>& rows) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) return fileError(path, "exists already");
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) !=
      SQLITE_OK) {
    sqlite3_close(db);
    return fileError(path, "cannot create");
  }
  const auto exec = [&](const char* sql) {
    return sqlite3_exec(db, sql, nullptr, nullptr, nullptr) == SQLITE_OK;
  };
  bool ok =
      exec("BEGIN") &&
      exec("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL)") &&
      exec("INSERT INTO schema VALUES (3, 'humble')") &&
      exec(
          "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT "
          "NULL, serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL)") &&
      exec(
          "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
          "timestamp INTEGER NOT NULL, data BLOB NOT NULL)");
  if (ok) {
    Statement t(db, "INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')");
    for (std::size_t i = 0; ok && i < topics.size(); ++i) {
      sqlite3_reset(t.get());
      sqlite3_bind_int64(t.get(), 1, static_cast<sqlite3_int64>(i + 1));
      sqlite3_bind_text(t.get(), 2, topics[i].name.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(t.get(), 3, topics[i].type.c_str(), -1, SQLITE_TRANSIENT);
      ok = t.ok() && sqlite3_step(t.get()) == SQLITE_DONE;
    }
    Statement m(db, "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)");
    for (std::size_t i = 0; ok && i < rows.size(); ++i) {
      sqlite3_reset(m.get());
      sqlite3_bind_int64(m.get(), 1, static_cast<sqlite3_int64>(rows[i].topic + 1));
      sqlite3_bind_int64(m.get(), 2, rows[i].timestamp);
      sqlite3_bind_blob(m.get(), 3, rows[i].data.data(), static_cast<int>(rows[i].data.size()),
                        SQLITE_TRANSIENT);
      ok = m.ok() && sqlite3_step(m.get()) == SQLITE_DONE;
    }
  }
  ok = ok && exec("COMMIT");
  const std::string error = ok ? "" : sqlite3_errmsg(db);
  sqlite3_close(db);
  if (!ok) {
    std::filesystem::remove(path, ec);
    return fileError(path, "cannot write the bag: " + error);
  }
  return {};
}

}  // namespace densemap::ros2
