#include <gtest/gtest.h>

#include <fstream>

#include "densemap/map/grid_map.hpp"
#include "densemap/map/map_diff.hpp"
#include "densemap/raycast/integrator.hpp"
#include "densemap/server/server_config.hpp"
#include "densemap/store/snapshot.hpp"
#include "densemap/test_support/data_dir.hpp"
#include "densemap/test_support/random_rays.hpp"
#include "densemap/wire/dds.hpp"

namespace densemap::server {
namespace {

std::filesystem::path writeConfig(const test::TempDir& dir, const std::string& text) {
  const auto p = dir.path() / "c.textproto";
  std::ofstream(p) << text;
  return p;
}

TEST(ServerConfig, TheShippedConfigIsValidAndEqualsTheDefaults) {
  auto config = loadServerConfig(DENSEMAP_EXAMPLE_CONFIG);
  ASSERT_TRUE(config) << config.error().message;
  auto options = pipelineOptions(*config);
  ASSERT_TRUE(options);
  auto defaults = pipelineOptions(proto::ServerConfig{});
  ASSERT_TRUE(defaults);
  EXPECT_EQ(options->resolution_m, defaults->resolution_m);
  EXPECT_EQ(options->max_range_m, defaults->max_range_m);
  EXPECT_EQ(ingestOptions(*config)->queue_depth, ingestOptions(proto::ServerConfig{})->queue_depth);
  EXPECT_EQ(options->method, defaults->method);
  EXPECT_EQ(defaults->method, IntegrationMethod::kRaycast);
  EXPECT_EQ(options->rule, UpdateRule::kSet);
  EXPECT_FALSE(options->kernel) << "log-odds is the default map kind";
  EXPECT_FALSE(options->upsample) << "no upsampling unless enabled";
  EXPECT_EQ(config->dds().network_interface(), "lo");
  auto ros2 = ros2Options(*config);
  ASSERT_TRUE(ros2);
  EXPECT_FALSE(*ros2) << "the ROS 2 face is off unless enabled";
}

TEST(ServerConfig, Ros2OptionsAndTheirErrors) {
  test::TempDir dir;
  auto options = [&](const std::string& text) {
    auto config = loadServerConfig(writeConfig(dir, text));
    EXPECT_TRUE(config) << config.error().message;
    return ros2Options(*config);
  };
  auto on = options("ros2 { enabled: true }\n");
  ASSERT_TRUE(on && *on);
  EXPECT_EQ((*on)->clouds, std::vector<std::string>{"/points"});
  EXPECT_EQ((*on)->world_frame, "map");
  EXPECT_FALSE((*on)->reliable_clouds);
  auto two = options(
      "ros2 { enabled: true clouds: \"/front/points\" clouds: \"rear\" world_frame: \"/odom\" }\n");
  ASSERT_TRUE(two && *two);
  EXPECT_EQ((*two)->clouds.size(), 2U);
  EXPECT_EQ((*two)->world_frame, "odom");
  // The ROS node's name and the gid layout of the robot's distribution.
  EXPECT_EQ((*on)->node_name, "densemap_server");
  EXPECT_EQ((*on)->gid_layout, RosGidLayout::kIronAndLater);
  auto humble = options("ros2 { enabled: true distro: \"humble\" node_name: \"map_2\" }\n");
  ASSERT_TRUE(humble && *humble);
  EXPECT_EQ((*humble)->gid_layout, RosGidLayout::kHumble);
  EXPECT_EQ((*humble)->node_name, "map_2");
  // Robots' namespaces, written as the user likes, kept in one form.
  auto fleet = options("ros2 { enabled: true robots: \"/robot1\" robots: \"robot_2\" }\n");
  ASSERT_TRUE(fleet && *fleet);
  EXPECT_EQ((*fleet)->robots, (std::vector<std::string>{"/robot1", "/robot_2"}));
  auto found = options("ros2 { enabled: true robot_pattern: \"/fleet/r?_*\" }\n");
  ASSERT_TRUE(found && *found);
  EXPECT_EQ((*found)->robot_pattern, "/fleet/r?_*");
  std::string too_many = "ros2 { enabled: true ";
  for (int i = 0; i <= 64; ++i) too_many += "robots: \"/r" + std::to_string(i) + "\" ";
  too_many += "}\n";
  std::string too_many_topics = "ros2 { enabled: true clouds: \"a\" clouds: \"b\" ";
  for (int i = 0; i < 33; ++i) too_many_topics += "robots: \"/r" + std::to_string(i) + "\" ";
  too_many_topics += "}\n";
  for (const std::string& bad : {too_many, too_many_topics}) {
    auto config = loadServerConfig(writeConfig(dir, bad));
    EXPECT_FALSE(config) << bad;
  }
  for (const char* bad :
       {"ros2 { enabled: true clouds: \"/bad topic\" }\n",
        "ros2 { enabled: true world_frame: \"\" }\n", "ros2 { enabled: true tf_wait_s: -1 }\n",
        "ros2 { enabled: true max_waiting_clouds: 0 }\n",
        "ros2 { enabled: true grid_min_z_m: 2 grid_max_z_m: 1 }\n",
        "ros2 { enabled: true octomap_topic: \"/a//b\" }\n",
        "ros2 { enabled: true distro: \"foxy\" }\n", "ros2 { enabled: true node_name: \"\" }\n",
        "ros2 { enabled: true node_name: \"2d_map\" }\n",
        "ros2 { enabled: true node_name: \"a/b\" }\n", "ros2 { enabled: true robots: \"/\" }\n",
        "ros2 { enabled: true robots: \"\" }\n", "ros2 { enabled: true robots: \"/robot 1\" }\n",
        "ros2 { enabled: true robots: \"/r1\" robots: \"r1\" }\n",
        "ros2 { enabled: true robots: \"/r1/\" }\n",
        "ros2 { enabled: true robot_pattern: \"robot*\" }\n",
        "ros2 { enabled: true robot_pattern: \"/robot *\" }\n"}) {
    // Refused at load, with the file's name (ros2 errors had none).
    const auto file = writeConfig(dir, bad);
    auto r = loadServerConfig(file);
    EXPECT_FALSE(r) << bad;
    if (!r) {
      EXPECT_NE(r.error().message.find("ros2"), std::string::npos) << r.error().message;
      EXPECT_NE(r.error().message.find(file.string()), std::string::npos) << r.error().message;
    }
  }
}

TEST(ServerConfig, SecurityBlockNeedsAllSixReadableFilesAndAllowsRemoteInterfaces) {
  const test::TempDir dir;
  const char* names[] = {"identity_ca",    "identity_certificate", "private_key",
                         "permissions_ca", "governance",           "permissions"};
  std::string block = "security {";
  for (const char* name : names) {
    std::ofstream(dir.path() / name) << "x";
    block += std::string(" ") + name + ": \"" + (dir.path() / name).string() + "\"";
  }
  block += " }\n";
  // Remote interface without security: refused, naming both ways out.
  auto refused = loadServerConfig(writeConfig(dir, "dds { network_interface: \"eth0\" }\n"));
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("security block"), std::string::npos);
  EXPECT_NE(refused.error().message.find("allow_insecure_remote"), std::string::npos);
  // With security: accepted, and the files come through.
  auto config = loadServerConfig(writeConfig(dir, "dds { network_interface: \"eth0\" }\n" + block));
  ASSERT_TRUE(config) << config.error().message;
  auto files = securityFiles(*config);
  ASSERT_TRUE(files && *files);
  EXPECT_EQ((*files)->permissions, (dir.path() / "permissions").string());
  EXPECT_EQ((*files)->identity_ca, (dir.path() / "identity_ca").string());
  auto none = securityFiles(proto::ServerConfig{});
  ASSERT_TRUE(none);
  EXPECT_FALSE(*none);
  // Each file missing in turn: the error names its field.
  for (const char* name : names) {
    std::filesystem::rename(dir.path() / name, dir.path() / "moved");
    auto missing = loadServerConfig(writeConfig(dir, block));
    ASSERT_FALSE(missing) << name;
    EXPECT_NE(missing.error().message.find(std::string("security.") + name + ":"),
              std::string::npos)
        << missing.error().message;
    std::filesystem::rename(dir.path() / "moved", dir.path() / name);
  }
}

TEST(ServerConfig, EvictionNeedsTheGridLogOddsMapAndAValidBox) {
  const test::TempDir dir;
  auto ok = loadServerConfig(
      writeConfig(dir,
                  "map { keep_radius_m: 40 bounds { min_x: -100 min_y: -100 min_z: -5 max_x: 100 "
                  "max_y: 100 max_z: 20 } }\n"));
  ASSERT_TRUE(ok) << ok.error().message;
  auto options = pipelineOptions(*ok);
  ASSERT_TRUE(options);
  EXPECT_EQ(options->keep_radius_m, 40.0);
  ASSERT_TRUE(options->bounds);
  EXPECT_EQ(options->bounds->first, Point3f(-100, -100, -5));
  EXPECT_EQ(options->bounds->second, Point3f(100, 100, 20));
  EXPECT_FALSE(pipelineOptions(proto::ServerConfig{})->bounds) << "no box unless configured";
  // Kernel maps evict too (their evidence blocks with the published grid's).
  EXPECT_TRUE(
      loadServerConfig(writeConfig(dir, "map { keep_radius_m: 40 kind: \"akimap_rays\" }\n")));
  for (const auto& [text, reason] : std::vector<std::pair<std::string, std::string>>{
           {"map { keep_radius_m: -1 }", "keep_radius_m must be >= 0"},
           {"map { keep_radius_m: 40 backend: \"octree\" }", "need backend \"grid\""},
           {"map { bounds { min_x: 1 max_x: 1 max_y: 1 max_z: 1 } }", "map.bounds needs"},
       }) {
    auto refused = loadServerConfig(writeConfig(dir, text + "\n"));
    ASSERT_FALSE(refused) << text;
    EXPECT_NE(refused.error().message.find(reason), std::string::npos) << refused.error().message;
  }
}

TEST(ServerConfig, HistoryCorrectedPathAndCatchUpOptionsAndTheirErrors) {
  const test::TempDir dir;
  EXPECT_FALSE(ingestOptions(proto::ServerConfig{})->history) << "off unless enabled";
  auto ok = loadServerConfig(
      writeConfig(dir,
                  "history { enabled: true directory: \"/tmp/h\" max_mb: 10 checkpoint_every: 20 "
                  "max_checkpoints: 3 threads: 2 }\n"));
  ASSERT_TRUE(ok) << ok.error().message;
  auto options = ingestOptions(*ok);
  ASSERT_TRUE(options && options->history);
  EXPECT_EQ(options->history->store.directory, "/tmp/h");
  EXPECT_EQ(options->history->store.max_bytes, std::size_t{10} << 20);
  EXPECT_EQ(options->history->checkpoint_every, 20U);
  EXPECT_EQ(options->history->max_checkpoints, 3U);
  EXPECT_EQ(options->history_threads, 2);
  EXPECT_TRUE(loadServerConfig(writeConfig(dir, "dds { instance: \"a\" catch_up_from: \"b\" }\n")));
  auto ros = loadServerConfig(
      writeConfig(dir,
                  "history { enabled: true } ros2 { enabled: true corrected_path_topic: \"/path\" "
                  "base_frame: \"/base\" }\n"));
  ASSERT_TRUE(ros) << ros.error().message;
  EXPECT_EQ((*ros2Options(*ros))->corrected_path_topic, "/path");
  EXPECT_EQ((*ros2Options(*ros))->base_frame, "base");
  for (const auto& [text, reason] : std::vector<std::pair<std::string, std::string>>{
           {"history { enabled: true directory: \"\" }", "history.directory"},
           {"history { enabled: true max_mb: 0 }", "history.max_mb"},
           {"history { enabled: true checkpoint_every: 0 }", "history.checkpoint_every"},
           {"history { enabled: true max_checkpoints: 2000 }", "history.max_checkpoints"},
           {"history { enabled: true threads: 0 }", "history.threads"},
           {"history { enabled: true } map { kind: \"akimap_rays\" }", "need map.kind log_odds"},
           {"history { enabled: true } map { decay { enabled: true } }", "without map.decay"},
           {"ros2 { enabled: true corrected_path_topic: \"/path\" }", "needs the map's history"},
           {"history { enabled: true } ros2 { enabled: true corrected_path_topic: \"no space\" }",
            "not a ROS topic name"},
           {"history { enabled: true } ros2 { enabled: true base_frame: \"/\" }",
            "ros2.base_frame"},
           {"dds { instance: \"a\" catch_up_from: \"a\" }", "dds.catch_up_from"},
           {"dds { catch_up_from: \"b\" }", "dds.catch_up_from"},
           {"dds { instance: \"a\" catch_up_from: \"b c\" }", "dds.catch_up_from"},
           {"dds { instance: \"a\" catch_up_from: \"b\" } map { kind: \"bgk\" }",
            "needs map.kind log_odds"},
       }) {
    auto refused = loadServerConfig(writeConfig(dir, text + "\n"));
    ASSERT_FALSE(refused) << text;
    EXPECT_NE(refused.error().message.find(reason), std::string::npos) << refused.error().message;
  }
}

TEST(DdsConfig, LoopbackStaysOnLoopbackOtherInterfacesDiscoverByMulticast) {
  for (const char* lo : {"lo", "127.0.0.1", "localhost", "::1"}) {
    EXPECT_TRUE(dds::isLoopbackInterface(lo)) << lo;
    const std::string xml = dds::domainConfig(lo);
    EXPECT_NE(xml.find("<AllowMulticast>false</AllowMulticast>"), std::string::npos) << xml;
    EXPECT_NE(xml.find("<Peer Address=\"127.0.0.1\"/>"), std::string::npos) << xml;
  }
  EXPECT_FALSE(dds::isLoopbackInterface("eth0"));
  const std::string eth = dds::domainConfig("eth0");
  EXPECT_NE(eth.find("<NetworkInterface name=\"eth0\"/>"), std::string::npos) << eth;
  EXPECT_EQ(eth.find("AllowMulticast"), std::string::npos) << eth;
  EXPECT_EQ(eth.find("127.0.0.1"), std::string::npos) << eth;
}

TEST(ServerConfig, ErrorsNameTheFileTheLineAndTheReason) {
  test::TempDir dir;
  auto unknown = loadServerConfig(writeConfig(dir, "map {\n  resolution_m: 0.1\n  colour: 3\n}\n"));
  ASSERT_FALSE(unknown);
  EXPECT_NE(unknown.error().message.find("c.textproto"), std::string::npos);
  EXPECT_NE(unknown.error().message.find("line 3"), std::string::npos);
  EXPECT_NE(unknown.error().message.find("colour"), std::string::npos);

  auto bad_value = loadServerConfig(writeConfig(dir, "map { resolution_m: -1 }\n"));
  ASSERT_FALSE(bad_value);
  EXPECT_NE(bad_value.error().message.find("resolution_m"), std::string::npos);
  // Errors found after parsing carry the field's line too, or the line of
  // the nearest enclosing block the file sets (a value left at its default).
  const std::pair<const char*, const char*> located[] = {
      {"# a comment\nmap {\n  resolution_m: 0.2\n  max_range_m: 5000\n}\n",
       "c.textproto: line 4, column 3: map.max_range_m"},
      {"map { resolution_m: 0.2 }\nros2 {\n  enabled: true\n  tf_wait_s: -4\n}\n",
       "c.textproto: line 4, column 3: ros2.tf_wait_s"},
      {"\n\nmap { keep_radius_m: 5 backend: \"octree\" }\n",
       "line 3, column 7: map.keep_radius_m"}};
  for (const auto& [text, expected] : located) {
    auto refused = loadServerConfig(writeConfig(dir, text));
    ASSERT_FALSE(refused) << text;
    EXPECT_NE(refused.error().message.find(expected), std::string::npos) << refused.error().message;
  }
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "map { backend: \"voxels\" }\n")));
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "pipeline { threads: 0 }\n")));
  auto bad_method = loadServerConfig(writeConfig(dir, "pipeline { integration: \"fast\" }\n"));
  ASSERT_FALSE(bad_method);
  EXPECT_NE(bad_method.error().message.find("superray+culling"), std::string::npos);
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "pipeline { update_rule: \"sum\" }\n")));
  auto per_ray = loadServerConfig(
      writeConfig(dir, "pipeline { integration: \"raycast\" update_rule: \"per_ray\" }\n"));
  ASSERT_TRUE(per_ray) << per_ray.error().message;
  EXPECT_EQ(pipelineOptions(*per_ray)->rule, UpdateRule::kPerRay);
  EXPECT_EQ(pipelineOptions(*per_ray)->method, IntegrationMethod::kRaycast);
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "map { sensor { prob_hit: 0.3 } }\n")));
  auto bad_kind = loadServerConfig(writeConfig(dir, "map { kind: \"gmm\" }\n"));
  ASSERT_FALSE(bad_kind);
  EXPECT_NE(bad_kind.error().message.find("akimap"), std::string::npos);
  auto akimap = loadServerConfig(writeConfig(dir, "map { kind: \"akimap\" }\n"));
  ASSERT_TRUE(akimap) << akimap.error().message;
  EXPECT_EQ(pipelineOptions(*akimap)->kernel, kernel::KernelMethod::kAkimap);
  EXPECT_NE(bad_kind.error().message.find("akimap_rays"), std::string::npos);
  auto rays = loadServerConfig(writeConfig(dir, "map { kind: \"akimap_rays\" }\n"));
  ASSERT_TRUE(rays) << rays.error().message;
  EXPECT_EQ(pipelineOptions(*rays)->kernel, kernel::KernelMethod::kAkimapRays);
  auto up = loadServerConfig(writeConfig(
      dir, "upsample { enabled: true method: \"nearest\" output_rows: 61 output_cols: 2048 }\n"));
  ASSERT_TRUE(up) << up.error().message;
  const auto up_options = pipelineOptions(*up)->upsample;
  ASSERT_TRUE(up_options);
  EXPECT_EQ(up_options->method, upsample::Interpolation::kNearest);
  EXPECT_EQ(up_options->input.rows, 16);
  EXPECT_EQ(up_options->output.rows, 61);
  EXPECT_EQ(up_options->output.cols, 2048);
  auto iln = loadServerConfig(writeConfig(
      dir, "upsample { enabled: true method: \"iln\" model: \"" DENSEMAP_ILN_MODEL "\" }\n"));
  ASSERT_TRUE(iln) << iln.error().message;
  const auto iln_options = pipelineOptions(*iln)->upsample;
  ASSERT_TRUE(iln_options && iln_options->iln);
  EXPECT_EQ(iln_options->method, upsample::Interpolation::kIln);
  auto no_model = loadServerConfig(writeConfig(
      dir, "upsample { enabled: true method: \"iln\" model: \"/nonexistent/iln.pb\" }\n"));
  ASSERT_FALSE(no_model);
  EXPECT_NE(no_model.error().message.find("/nonexistent/iln.pb"), std::string::npos);
  // The ILN model is only loaded when upsampling is on.
  EXPECT_TRUE(loadServerConfig(writeConfig(
      dir, "upsample { enabled: false method: \"iln\" model: \"/nonexistent/iln.pb\" }\n")));
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "upsample { enabled: true input_rows: 1 }\n")));
  EXPECT_FALSE(loadServerConfig(
      writeConfig(dir, "upsample { enabled: true top_deg: -20 bottom_deg: 10 }\n")));
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "dds { network_interface: \"\" }\n")));
  EXPECT_FALSE(loadServerConfig(writeConfig(dir, "map { resolution_m: \"x\" }\n")));
  EXPECT_FALSE(loadServerConfig(dir.path() / "missing.textproto"));
}

}  // namespace
}  // namespace densemap::server
