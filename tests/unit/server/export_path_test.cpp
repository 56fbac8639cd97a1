#include <gtest/gtest.h>

#include <filesystem>

#include "densemap/server/export_path.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap::server {
namespace {

namespace fs = std::filesystem;

TEST(ExportPath, PlainNamesLandInTheExportDirectory) {
  test::TempDir dir;
  const fs::path exports = dir.path() / "exports";
  for (const char* name : {"map.dmap", "a-b_c.1.bt", "X.ot"}) {
    auto file = confineExportPath(exports, name);
    ASSERT_TRUE(file) << name << ": " << file.error().message;
    EXPECT_EQ(file->parent_path(), exports);
    EXPECT_EQ(file->filename(), name);
  }
  EXPECT_TRUE(fs::is_directory(exports));
}

TEST(ExportPath, PathsTraversalHiddenNamesAndOtherKindsAreRefused) {
  test::TempDir dir;
  for (const std::string& name :
       {std::string("/etc/passwd"), std::string("../x.dmap"), std::string("a/b.dmap"),
        std::string(".."), std::string("."), std::string(".x.dmap"), std::string(""),
        std::string("x.txt"), std::string("x"), std::string("a b.dmap"), std::string("x.dmap\n"),
        std::string("x\0.dmap", 7), std::string(129, 'a')}) {
    EXPECT_FALSE(confineExportPath(dir.path(), name)) << name;
  }
}

TEST(ExportPath, ALinkOrFileWhereTheDirectoryShouldBeIsRefused) {
  test::TempDir dir;
  fs::create_directory(dir.path() / "real");
  fs::create_directory_symlink(dir.path() / "real", dir.path() / "link");
  EXPECT_FALSE(confineExportPath(dir.path() / "link", "m.dmap"));
  EXPECT_FALSE(confineExportPath("", "m.dmap"));  // nothing configured: named saves are off
}

TEST(ExportPath, TheDefaultIsExportsBesideTheSnapshot) {
  EXPECT_EQ(exportDirectory("", "/var/lib/densemap/map.dmap"), "/var/lib/densemap/exports");
  EXPECT_EQ(exportDirectory("", "map.dmap"), fs::path("./exports"));
  EXPECT_EQ(exportDirectory("/srv/out", "map.dmap"), "/srv/out");
  EXPECT_EQ(exportDirectory("", ""), fs::path());
}

}  // namespace
}  // namespace densemap::server
