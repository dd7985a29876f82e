// The catalogue of bad inputs (issue "hostile input never crashes, never writes NaN silently,
// never escapes its folder"): tests/catalogue/cases.json lists each case's input files (from
// tests/catalogue/files/), the grains command line, the exit code and a fragment of the message
// it must print. This one test runs every case with the built binary in a fresh folder and checks
// that it was not killed by a signal, that the exit code and the message are the expected ones,
// that no frame_*.ply or .csv it wrote holds a number that is not finite, and that it wrote
// nothing outside the case's output folder. tests/catalogue/README.md says how a case is written;
// GRAINS_CATALOGUE_CASE=NAME runs only the cases whose name contains NAME.
#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

const std::string kCatalogue = std::string(GRAINS_SOURCE_DIR) + "/tests/catalogue";
// a case that runs longer than this is a hang: it is killed and fails
constexpr double kTimeoutSeconds = 30;

std::string read_text(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Replaces {dir}, {out}, {file} and {files} (the catalogue's files folder) in text.
std::string expand(std::string text, const std::map<std::string, std::string>& vars) {
  for (const auto& [key, value] : vars)
    for (size_t at = text.find(key); at != std::string::npos;
         at = text.find(key, at + value.size()))
      text.replace(at, key.size(), value);
  return text;
}

// A command line split at spaces; '...' keeps its spaces (and loses its quotes), '' is an empty
// argument.
std::vector<std::string> split_args(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool in_arg = false, quoted = false;
  for (char c : line) {
    if (c == '\'') {
      quoted = !quoted;
      in_arg = true;
    } else if (c == ' ' && !quoted) {
      if (in_arg) out.push_back(cur);
      cur.clear();
      in_arg = false;
    } else {
      cur += c;
      in_arg = true;
    }
  }
  if (in_arg) out.push_back(cur);
  return out;
}

struct Outcome {
  bool signalled = false;  // killed by a signal (a crash), or by us after the timeout
  int signal = 0;
  bool timed_out = false;
  int exit_code = -1;
  std::string output;  // stdout then stderr
  double seconds = 0;
};

// The binary a case's `program` names: grains (the default) or grains-lab; "" for another name.
std::string binary_of(const json& c) {
  const std::string program = c.value("program", "grains");
  if (program == "grains") return GRAINS_BINARY;
  if (program == "grains-lab") return GRAINS_LAB_BINARY;
  return "";
}

// Runs `binary` with args in folder cwd; stdin is /dev/null.
Outcome run_binary(const std::string& binary, const std::vector<std::string>& args,
                   const fs::path& cwd, const fs::path& log_dir) {
  const std::string out_log = (log_dir / "stdout").string(),
                    err_log = (log_dir / "stderr").string();
  std::vector<std::string> full = {binary};
  full.insert(full.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : full) argv.push_back(a.data());
  argv.push_back(nullptr);
  // the environment, with one OpenMP thread that does not spin, as under CTest
  std::vector<std::string> vars = {"OMP_NUM_THREADS=1", "OMP_WAIT_POLICY=passive"};
  for (char** e = environ; *e; ++e)
    if (!std::string_view(*e).starts_with("OMP_NUM_THREADS=") &&
        !std::string_view(*e).starts_with("OMP_WAIT_POLICY="))
      vars.emplace_back(*e);
  std::vector<char*> envp;
  for (std::string& v : vars) envp.push_back(v.data());
  envp.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    // the child: only async-signal-safe calls until exec
    int in = open("/dev/null", O_RDONLY);
    int out = open(out_log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    int err = open(err_log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (in < 0 || out < 0 || err < 0 || chdir(cwd.c_str()) != 0) _exit(127);
    dup2(in, 0);
    dup2(out, 1);
    dup2(err, 2);
    execve(argv[0], argv.data(), envp.data());
    _exit(127);
  }
  Outcome o;
  if (pid < 0) return o;
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (o.seconds > kTimeoutSeconds && !o.timed_out) {
      o.timed_out = true;
      kill(pid, SIGKILL);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  o.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (WIFSIGNALED(status)) {
    o.signalled = true;
    o.signal = WTERMSIG(status);
  } else if (WIFEXITED(status)) {
    o.exit_code = WEXITSTATUS(status);
  }
  o.output = read_text(out_log) + read_text(err_log);
  return o;
}

// Every path under root (files and folders), relative to it.
std::set<std::string> listing(const fs::path& root) {
  std::set<std::string> out;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(root, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    out.insert(fs::relative(it->path(), root).string());
  return out;
}

// A field that reads wholly as a number that is not finite ("nan", "-inf", "1e999").
bool non_finite_text(const std::string& field) {
  if (field.empty()) return false;
  char* end = nullptr;
  const double v = std::strtod(field.c_str(), &end);
  return end == field.c_str() + field.size() && !std::isfinite(v);
}

// The first number in a CSV file that is not finite, as "line L: 'text'", or "".
std::string csv_non_finite(const fs::path& p) {
  std::istringstream in(read_text(p));
  std::string line;
  for (int l = 1; std::getline(in, line); ++l) {
    std::stringstream fields(line);
    for (std::string f; std::getline(fields, f, ',');)
      if (non_finite_text(f)) return "line " + std::to_string(l) + ": '" + f + "'";
  }
  return "";
}

// The first number in a PLY file (ascii or binary, any endianness) that is not finite, as
// "element E row R property P", or a reason the file could not be read, or "".
std::string ply_non_finite(const fs::path& p) {
  const std::string data = read_text(p);
  struct Prop {
    std::string name, type, count_type;  // count_type non-empty for a list
  };
  struct Element {
    std::string name;
    size_t count = 0;
    std::vector<Prop> props;
  };
  std::vector<Element> elements;
  std::string format;
  size_t pos = 0;
  for (;;) {
    const size_t e = data.find('\n', pos);
    if (e == std::string::npos) return "no end_header";
    std::istringstream line(data.substr(pos, e - pos));
    pos = e + 1;
    std::string kw;
    line >> kw;
    if (kw == "end_header") break;
    if (kw == "format") line >> format;
    if (kw == "element") {
      elements.push_back({});
      line >> elements.back().name >> elements.back().count;
    }
    if (kw == "property" && !elements.empty()) {
      Prop pr;
      line >> pr.type;
      if (pr.type == "list") line >> pr.count_type >> pr.type;
      line >> pr.name;
      elements.back().props.push_back(pr);
    }
  }
  auto size_of = [](const std::string& t) -> size_t {
    if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
    if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
    if (t == "double" || t == "float64") return 8;
    return 4;
  };
  const bool ascii = format == "ascii";
  const bool swap = (format == "binary_big_endian") == (std::endian::native == std::endian::little);
  std::istringstream text(ascii ? data.substr(pos) : std::string());
  auto raw = [&](const std::string& type, double& v) {
    const size_t n = size_of(type);
    if (pos + n > data.size()) return false;
    unsigned char b[8];
    std::memcpy(b, data.data() + pos, n);
    pos += n;
    if (swap) std::reverse(b, b + n);
    if (type == "float" || type == "float32") {
      float f;
      std::memcpy(&f, b, 4);
      v = f;
    } else if (type == "double" || type == "float64") {
      double d;
      std::memcpy(&d, b, 8);
      v = d;
    } else {  // an integer (a list's length): little-endian bytes once swapped
      v = 0;
      for (size_t k = n; k-- > 0;) v = v * 256 + b[k];
    }
    return true;
  };
  auto next = [&](const std::string& type, double& v) {
    if (!ascii) return raw(type, v);
    std::string tok;
    if (!(text >> tok)) return false;
    v = std::strtod(tok.c_str(), nullptr);
    return true;
  };
  for (const Element& el : elements)
    for (size_t r = 0; r < el.count; ++r)
      for (const Prop& pr : el.props) {
        double v = 0;
        size_t items = 1;
        if (!pr.count_type.empty()) {
          if (!next(pr.count_type, v)) return "truncated";
          items = static_cast<size_t>(v);
        }
        for (size_t k = 0; k < items; ++k) {
          if (!next(pr.type, v)) return "truncated";
          if (!std::isfinite(v))
            return "element " + el.name + " row " + std::to_string(r) + " property " + pr.name;
        }
      }
  return "";
}

// Makes a case's inputs in its folder: the files copied from files/ (keeping their names), then
// the setup steps. Returns the path {file} stands for (the first of them), or "" on a bad entry.
std::string make_inputs(const json& c, const fs::path& dir) {
  std::string first;
  for (const json& f : c.value("files", json::array())) {
    const fs::path src = fs::path(kCatalogue) / "files" / f.get<std::string>();
    INFO("input file " << src.string());
    CHECK(fs::is_regular_file(src));
    if (!fs::is_regular_file(src)) return "";
    fs::copy_file(src, dir / src.filename(), fs::copy_options::overwrite_existing);
    if (first.empty()) first = (dir / src.filename()).string();
  }
  for (const json& s : c.value("setup", json::array())) {
    const fs::path target = dir / s.at("path").get<std::string>();
    const std::string what = s.at("make").get<std::string>();
    if (what == "folder") {
      fs::create_directories(target);
    } else if (what == "fifo") {
      if (mkfifo(target.c_str(), 0644) != 0) return "";
    } else if (what == "copy") {
      // a file of the catalogue under another name (a frame_0001.ply for render)
      fs::copy_file(fs::path(kCatalogue) / "files" / s.at("from").get<std::string>(), target);
    } else if (what == "sparse") {
      // a file of `size` bytes that takes no room (an input over a size limit)
      std::ofstream(target).close();
      fs::resize_file(target, s.at("size").get<uintmax_t>());
    } else if (what == "text") {
      // "parts": [[TEXT, TIMES], ...], each TEXT written TIMES times, with {k} and {k+1} the
      // repetition's number from 0 (deep nesting, long names, long chains of nodes)
      std::ofstream o(target, std::ios::binary);
      for (const json& part : s.at("parts"))
        for (int k = 0; k < part.at(1).get<int>(); ++k)
          o << expand(part.at(0).get<std::string>(),
                      {{"{k}", std::to_string(k)}, {"{k+1}", std::to_string(k + 1)}});
    } else {
      INFO("unknown setup step '" << what << "'");
      CHECK(false);
      return "";
    }
    if (first.empty()) first = target.string();
  }
  return first;
}

bool under(const std::string& path, const std::string& folder) {
  return path == folder || path.starts_with(folder + "/");
}

// Runs one case in root/cases/NAME/case; true when every check passed.
bool run_case(const json& c, const fs::path& root) {
  const std::string name = c.at("name").get<std::string>();
  // two levels below the sandbox, so that an escape through "../.." still lands where the
  // listing of root sees it
  const fs::path dir = root / "cases" / name / "case";
  const fs::path out = dir / "out";
  fs::create_directories(dir);
  std::map<std::string, std::string> vars = {
      {"{dir}", dir.string()}, {"{out}", out.string()}, {"{files}", kCatalogue + "/files"}};
  const std::string binary = binary_of(c);
  INFO("program: " << c.value("program", "grains"));
  CHECK_FALSE(binary.empty());
  if (binary.empty()) return false;
  const bool has_inputs = c.contains("files") || c.contains("setup");
  vars["{file}"] = make_inputs(c, dir);
  if (has_inputs && vars["{file}"].empty()) return false;
  for (const json& b : c.value("before", json::array())) {
    const Outcome o =
        run_binary(binary, split_args(expand(b.get<std::string>(), vars)), dir, root / "logs");
    INFO("before: " << b.get<std::string>() << "\n" << o.output);
    CHECK(o.exit_code == 0);
    if (o.exit_code != 0) return false;
  }

  const std::set<std::string> before = listing(root);
  const std::string args = expand(c.at("args").get<std::string>(), vars);
  const Outcome o = run_binary(binary, split_args(args), dir, root / "logs");
  const int expect = c.at("exit").get<int>();
  const std::string message = expand(c.at("message").get<std::string>(), vars);
  INFO(c.value("program", "grains") << " " << args << "\n" << o.output);
  CHECK_FALSE(o.timed_out);
  INFO("killed by signal " << o.signal);
  CHECK_FALSE(o.signalled);
  CHECK(o.exit_code == expect);
  CHECK_THAT(o.output, Catch::Contains(message));
  bool ok = !o.timed_out && !o.signalled && o.exit_code == expect &&
            o.output.find(message) != std::string::npos;

  // nothing new outside the output folder, except what `allow` names (a video beside it)
  const std::string out_rel = fs::relative(out, root).string();
  std::set<std::string> allowed = {out_rel};
  for (const json& a : c.value("allow", json::array()))
    allowed.insert(fs::relative(dir / a.get<std::string>(), root).string());
  for (const std::string& p : listing(root)) {
    if (under(p, "logs")) continue;
    const bool fresh = !before.count(p);
    bool inside = false;
    for (const std::string& a : allowed) inside = inside || under(p, a);
    if (fresh) {
      INFO("written outside the output folder: " << p);
      CHECK(inside);
      ok = ok && inside;
    }
    // no number that is not finite in what the program wrote (now or in a `before` step): the
    // output folder and anything new; the case's own inputs may hold NaN on purpose
    const fs::path path = root / p;
    if (!(fresh || under(p, out_rel)) || !fs::is_regular_file(path)) continue;
    const std::string file = path.filename().string();
    std::string bad;
    if (path.extension() == ".csv") bad = csv_non_finite(path);
    if (file.starts_with("frame_") && path.extension() == ".ply") bad = ply_non_finite(path);
    INFO("not finite in " << path.string() << ": " << bad);
    CHECK(bad.empty());
    ok = ok && bad.empty();
  }
  // the frames a case expects in its output folder (those written before a failure stay)
  if (c.contains("frames")) {
    int frames = 0;
    for (const std::string& p : listing(out))
      frames += fs::path(p).filename().string().starts_with("frame_") &&
                fs::path(p).extension() == ".ply";
    CHECK(frames == c["frames"].get<int>());
    ok = ok && frames == c["frames"].get<int>();
  }
  // a refusal before the run starts leaves no output folder
  if (c.contains("out_exists")) {
    const bool exists = fs::exists(out);
    CHECK(exists == c["out_exists"].get<bool>());
    ok = ok && exists == c["out_exists"].get<bool>();
  }
  return ok;
}

}  // namespace

TEST_CASE(
    "the catalogue of bad inputs: no crash, the right exit code and message, no NaN "
    "written, nothing outside the output folder",
    "[cli][hostile][catalogue]") {
  // the checkers themselves find what they look for
  REQUIRE_FALSE(ply_non_finite(kCatalogue + "/files/binary/y_minus_inf_big_endian.ply").empty());
  REQUIRE_FALSE(ply_non_finite(kCatalogue + "/files/binary/double_z_nan.ply").empty());
  REQUIRE(ply_non_finite(kCatalogue + "/files/binary/ok_big_endian.ply").empty());
  REQUIRE(non_finite_text("-nan"));
  REQUIRE_FALSE(non_finite_text("1e38"));
  REQUIRE(non_finite_text("-inf"));

  const json manifest = json::parse(read_text(kCatalogue + "/cases.json"));
  REQUIRE(manifest.contains("cases"));
  const char* only = std::getenv("GRAINS_CATALOGUE_CASE");
  const fs::path root =
      fs::temp_directory_path() / ("grains_catalogue_" + std::to_string(getpid()));
  fs::remove_all(root);
  fs::create_directories(root / "logs");

  std::set<std::string> names;
  std::vector<std::string> failed;
  int ran = 0;
  for (const json& c : manifest["cases"]) {
    const std::string name = c.at("name").get<std::string>();
    INFO("case " << name);
    CHECK(names.insert(name).second);  // names are unique
    if (only && name.find(only) == std::string::npos) continue;
    ++ran;
    if (run_case(c, root))
      fs::remove_all(root / "cases" / name);
    else
      failed.push_back(name);
  }
  std::string list;
  for (const std::string& f : failed) list += "\n  " + f;
  INFO(failed.size() << " of " << ran << " cases failed (their folders are left in "
                     << (root / "cases").string() << "):" << list);
  CHECK(failed.empty());
  CHECK(ran > 0);
  if (failed.empty()) fs::remove_all(root);
}
