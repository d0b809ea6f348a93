#pragma once
// The calibration report of `trbc calibrate`: one document rendered twice, as
// OUT/report.md (figures linked) and as a self-contained OUT/report.html (figures embedded as
// base64 PNG). It is assembled from the files the pipeline's stages leave in OUT (posterior
// statistics, corner plot, predictive bands and coverage, Sobol' indices, surrogate accuracy,
// calibrated cell, stage ledger); a section whose inputs are missing says so instead of vanishing.
#include <filesystem>
#include <string>
#include <vector>

namespace trbc {

/// A small document model: headings, paragraphs (with `code` spans), tables, images, code blocks.
class ReportDocument {
public:
    void heading(int level, std::string text);
    void paragraph(std::string text);
    void table(std::vector<std::string> header, std::vector<std::vector<std::string>> rows);
    void image(std::filesystem::path file, std::string caption);
    void code(std::string text);

    /// Markdown; image paths relative to `directory` (where report.md is written).
    std::string markdown(const std::filesystem::path& directory) const;
    /// Self-contained HTML (inline CSS, images as data URIs; a missing image becomes a note).
    std::string html(const std::string& title) const;

private:
    enum class Kind { Heading, Paragraph, Table, Image, Code };
    struct Block {
        Kind kind;
        int level = 0;
        std::string text;
        std::vector<std::string> header;
        std::vector<std::vector<std::string>> rows;
        std::filesystem::path file;
    };
    std::vector<Block> blocks_;
};

std::string base64Encode(const std::string& bytes);

/// One `trbc simulate` record of the mesh-convergence set: DIR/<point>_L<level>.json.
struct MeshConvergenceRecord {
    std::filesystem::path file;
    std::string point;
    int level = 0;
};

/// The records of `directory` sorted by file name; other files are not records. An absent
/// directory has none.
std::vector<MeshConvergenceRecord> meshConvergenceRecords(const std::filesystem::path& directory);

struct CalibrationReportInputs {
    std::filesystem::path outputDirectory;     ///< OUT of trbc calibrate
    std::filesystem::path configFile;
    std::vector<std::filesystem::path> configBases;  ///< the configurations it overrides (base = ...), nearest first
    std::filesystem::path surrogateDirectory;  ///< holds accuracy.json
    std::filesystem::path meshConvergenceDirectory;  ///< trbc simulate JSONs <point>_L<level>.json (optional)
    std::vector<std::string> dataSets;         ///< "name (experiment): file"
    std::string version;
};

/// Writes OUT/report.md and OUT/report.html; returns the document.
ReportDocument writeCalibrationReport(const CalibrationReportInputs& in);

}  // namespace trbc
