// `grains plot RUN`: a run's stats.csv (docs/output-format.md) drawn over time as one PNG of
// stacked charts, for a person to look at rather than read: kinetic energy, penetration (max and
// mean), the substeps error control took, its error, and the largest constraint strain. With
// several solvers (one sub-folder each, as `grains run` writes them) each chart has a curve per
// solver. Reads stats.csv alone.
#pragma once
#include <string>
#include <vector>

#include "viewer-offline/image.h"

namespace CLI {
class App;
}

namespace grains::viewer {

// One stats.csv, by column name (a column the file lacks is absent); `name` labels its curves.
struct StatsTable {
  std::string name;
  std::vector<std::string> columns;
  std::vector<std::vector<double>> values;  // (columns x rows)
  const std::vector<double>* column(const std::string& c) const;
  size_t rows() const { return values.empty() ? 0 : values[0].size(); }
};

// Reads DIR/stats.csv. Throws LoadError (the file, its line and what is wrong) for a missing
// file, a header without frame and time, a row of another length or a field that is not a number.
StatsTable read_stats(const std::string& path, const std::string& name);

// The charts of `tables` (one curve each) on a width x height image, titled `title`.
Image plot_stats(const std::vector<StatsTable>& tables, const std::string& title, int width,
                 int height);

struct PlotOptions {
  std::string run;   // the run's folder: DIR/stats.csv, or one sub-folder per solver
  std::string out;   // the PNG (default RUN/stats.png)
  std::string size = "1200x1300";
  bool quiet = false, verbose = false;
};

// Throws LoadError for bad input (exit 2), std::runtime_error when the PNG cannot be written.
int plot_command(const PlotOptions& opts);

// Adds the `plot` subcommand's arguments to a CLI11 app, bound to `opts`.
CLI::App* add_plot_subcommand(CLI::App& app, PlotOptions& opts);

}  // namespace grains::viewer
