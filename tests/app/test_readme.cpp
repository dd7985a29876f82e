// The README as a user meets it: its example graph is the demo graph, the commands of its example
// run as written and leave the files it names, every command line it shows is a subcommand the
// programs have with the options it lists, and it stays short.
#include <catch2/catch.hpp>
#include <algorithm>
#include <filesystem>
#include <regex>
#include <sstream>

#include "tests/support/support.h"

namespace fs = std::filesystem;
using namespace grains;

namespace {

// The fenced blocks of a Markdown text: (language, body) in order.
std::vector<std::pair<std::string, std::string>> fenced_blocks(const std::string& text) {
  std::vector<std::pair<std::string, std::string>> out;
  std::istringstream in(text);
  std::string line, lang, body;
  bool inside = false;
  while (std::getline(in, line)) {
    if (line.rfind("```", 0) == 0) {
      if (inside) out.emplace_back(lang, body);
      else lang = line.substr(3), body.clear();
      inside = !inside;
      continue;
    }
    if (inside) body += line + "\n";
  }
  return out;
}

std::vector<std::string> lines_of(const std::string& body) {
  std::vector<std::string> out;
  std::istringstream in(body);
  for (std::string line; std::getline(in, line);)
    if (!line.empty()) out.push_back(line);
  return out;
}

// The block that follows the first line holding `heading`.
std::string section(const std::string& text, const std::string& heading) {
  const size_t at = text.find(heading);
  REQUIRE(at != std::string::npos);
  return text.substr(at);
}

}  // namespace

TEST_CASE("the README's example graph is graphs/default.json", "[cli][readme]") {
  const std::string readme = test::read_text(test::source_dir() + "/README.md");
  const auto blocks = fenced_blocks(section(readme, "## An example"));
  REQUIRE(!blocks.empty());
  CHECK(blocks[0].first == "json");
  CHECK(blocks[0].second == test::read_text(test::source_dir() + "/graphs/default.json"));
}

TEST_CASE("the README's example commands run as written and leave the files it names",
          "[cli][readme]") {
  const std::string readme = test::read_text(test::source_dir() + "/README.md");
  const auto blocks = fenced_blocks(section(readme, "## An example"));
  REQUIRE(blocks.size() >= 2);
  const std::vector<std::string> commands = lines_of(blocks[1].second);
  REQUIRE(commands.size() == 3);
  // run from a fresh folder that holds the repository's graphs, so out/ lands there
  const std::string dir = test::temp_dir("readme");
  fs::create_directories(dir + "/graphs");
  fs::copy_file(test::source_dir() + "/graphs/default.json", dir + "/graphs/default.json");
  for (const std::string& command : commands) {
    INFO(command);
    REQUIRE(command.rfind("build/grains ", 0) == 0);
    const std::string args = command.substr(std::string("build/grains ").size());
    // the binary's own paths are relative to the folder it runs in: cd there first
    const std::string line = "cd '" + dir + "' && '" + GRAINS_BINARY + "' " + args + " > '" + dir +
                             "/log.txt' 2>&1";
    CHECK(std::system(line.c_str()) == 0);
  }
  for (const char* file : {"out/first/frame_0001.ply", "out/first/frame_0012.ply", "out/first/stats.csv",
                           "out/first/collider_poses.csv", "out/first/render/contact_sheet.png",
                           "out/first/render/frame_0012.png"}) {
    INFO(file);
    CHECK(fs::is_regular_file(dir + "/" + file));
  }

  // "Viewing results", on the run the example made: grains' own commands run as written (the
  // text after '#' is a comment); the ParaView line needs the graph's output to ask for vtp, as
  // it says, and then frames.pvd names frames that exist (ParaView itself is not installed here;
  // the vtk_client test opens such a run with VTK's reader)
  const auto viewing = fenced_blocks(section(readme, "## Viewing results"));
  REQUIRE(!viewing.empty());
  std::vector<std::string> view_commands = lines_of(viewing[0].second);
  REQUIRE(view_commands.size() == 3);
  for (std::string command : view_commands) {
    command = command.substr(0, command.find('#'));
    while (!command.empty() && command.back() == ' ') command.pop_back();
    INFO(command);
    if (command.rfind("paraview ", 0) == 0) {
      CHECK(command == "paraview out/first/frames.pvd");
      CHECK(viewing[0].second.find("\"formats\": [\"ply\", \"vtp\"]") != std::string::npos);
      continue;
    }
    REQUIRE(command.rfind("build/grains ", 0) == 0);
    const std::string args = command.substr(std::string("build/grains ").size());
    const std::string line = "cd '" + dir + "' && '" + GRAINS_BINARY + "' " + args + " > '" + dir +
                             "/log.txt' 2>&1";
    CHECK(std::system(line.c_str()) == 0);
  }
  for (const char* file : {"out/first/first.mp4", "out/first/stats.png"}) {
    INFO(file);
    CHECK(fs::is_regular_file(dir + "/" + file));
    CHECK(fs::file_size(dir + "/" + file) > 1000);
  }
  // the graph with "formats": ["ply", "vtp"] in its output, as the ParaView line says
  std::string graph = test::read_text(dir + "/graphs/default.json");
  const std::string output = "\"output\": {";
  const size_t at = graph.find(output);
  REQUIRE(at != std::string::npos);
  graph.insert(at + output.size(), "\"formats\": [\"ply\", \"vtp\"], ");
  test::write_file(dir + "/graphs", "vtp.json", graph);
  const std::string line = "cd '" + dir + "' && '" + GRAINS_BINARY +
                           "' run graphs/vtp.json --out out/first --frames 3 --quiet --overwrite > '" +
                           dir + "/log.txt' 2>&1";
  REQUIRE(std::system(line.c_str()) == 0);
  const std::string pvd = test::read_text(dir + "/out/first/frames.pvd");
  for (const char* frame : {"frame_0001.vtp", "frame_0003.vtp"}) {
    INFO(frame);
    CHECK(pvd.find(frame) != std::string::npos);
    CHECK(fs::is_regular_file(dir + "/out/first/" + frame));
  }
}

TEST_CASE("every command line the README shows is a subcommand with the options it lists",
          "[cli][readme]") {
  const std::string readme = test::read_text(test::source_dir() + "/README.md");
  const auto blocks = fenced_blocks(section(readme, "## Command line"));
  REQUIRE(!blocks.empty());
  const std::vector<std::string> commands = lines_of(blocks[0].second);
  CHECK(commands.size() >= 10);
  const std::string dir = test::temp_dir("readme_help");
  const std::regex option("--[a-z][a-z-]*");
  for (const std::string& command : commands) {
    INFO(command);
    std::istringstream words(command);
    std::string program, sub;
    words >> program >> sub;
    const std::string log = dir + "/help.txt";
    int rc = -1;
    if (program == "build/grains") rc = test::run_grains(sub + " --help", log);
    else if (program == "build/grains-lab") rc = test::run_lab(sub + " --help", log);
    REQUIRE(rc == 0);
    const std::string help = test::read_text(log);
    for (std::sregex_iterator m(command.begin(), command.end(), option), end; m != end; ++m) {
      INFO(m->str());
      CHECK(help.find(m->str()) != std::string::npos);
    }
  }
  // the set-up commands are Makefile targets
  const std::string makefile = test::read_text(test::source_dir() + "/Makefile");
  CHECK(makefile.find("\ndemo:") != std::string::npos);
  CHECK(makefile.find("\ntest:") != std::string::npos);
}

TEST_CASE("the README stays short", "[cli][readme]") {
  const std::string readme = test::read_text(test::source_dir() + "/README.md");
  CHECK(std::count(readme.begin(), readme.end(), '\n') < 200);
}
