#include <bzlib.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include "densemap/io/file_bytes.hpp"
#include "densemap/test_support/data_dir.hpp"

namespace densemap {
namespace {

namespace fs = std::filesystem;

TEST(ReadFileBytes, ADirectoryIsAClearErrorNotAnException) {
  test::TempDir dir;
  const auto read = readFileBytes(dir.path());
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("is a directory"), std::string::npos) << read.error().message;
}

TEST(ReadFileBytes, DevicesAndFifosAreRefused) {
  test::TempDir dir;
  const fs::path fifo = dir.path() / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto read = readFileBytes(fifo);  // would block forever if read as a file
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("not a regular file"), std::string::npos);
}

TEST(ReadFileBytes, FilesOverTheLimitAreRefusedBeforeTheyAreRead) {
  test::TempDir dir;
  const fs::path file = dir.path() / "f.bin";
  std::ofstream(file) << std::string(1000, 'x');
  EXPECT_TRUE(readFileBytes(file, 1000));
  const auto read = readFileBytes(file, 999);
  ASSERT_FALSE(read);
  EXPECT_NE(read.error().message.find("over the limit of 999 bytes"), std::string::npos)
      << read.error().message;
}

TEST(ReadFileBytes, Bzip2ThatExpandsPastTheLimitIsRefused) {
  test::TempDir dir;
  const std::string plain(1 << 20, 'a');  // 1 MiB of one letter: a few dozen bytes compressed
  std::vector<char> packed(plain.size());
  unsigned packed_size = static_cast<unsigned>(packed.size());
  ASSERT_EQ(BZ2_bzBuffToBuffCompress(packed.data(), &packed_size, const_cast<char*>(plain.data()),
                                     static_cast<unsigned>(plain.size()), 9, 0, 0),
            BZ_OK);
  const fs::path file = dir.path() / "bomb.txt.bz2";
  std::ofstream(file, std::ios::binary).write(packed.data(), packed_size);
  auto whole = readFileBytes(file);
  ASSERT_TRUE(whole) << whole.error().message;
  EXPECT_EQ(*whole, plain);
  const auto capped = readFileBytes(file, 100'000);
  ASSERT_FALSE(capped);
  EXPECT_NE(capped.error().message.find("decompresses to more than"), std::string::npos);
}

TEST(WriteFileAtomically, ConcurrentWritersOfOnePathNeverShareATemporaryFile) {
  test::TempDir dir;
  const fs::path file = dir.path() / "m.dmap";
  std::vector<std::thread> writers;
  std::atomic<int> failures{0};
  for (int w = 0; w < 4; ++w) {
    writers.emplace_back([&, w] {
      const std::string bytes(200'000, static_cast<char>('a' + w));
      for (int i = 0; i < 50; ++i) failures += !writeFileAtomically(file, bytes);
    });
  }
  for (auto& t : writers) t.join();
  EXPECT_EQ(failures.load(), 0);
  // The survivor is one writer's whole content, never a mix; no temporary file is left.
  const auto read = readFileBytes(file);
  ASSERT_TRUE(read);
  ASSERT_EQ(read->size(), 200'000U);
  EXPECT_EQ(read->find_first_not_of(read->front()), std::string::npos);
  for (const auto& entry : fs::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename(), "m.dmap") << "left behind: " << entry.path();
  }
}

TEST(WriteFileAtomically, TheModeIsExactlyTheOneAsked) {
  test::TempDir dir;
  const fs::path file = dir.path() / "private.dmap";
  ASSERT_TRUE(writeFileAtomically(file, "x", 0600));
  struct stat st {};
  ASSERT_EQ(::stat(file.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600U);
}

}  // namespace
}  // namespace densemap
