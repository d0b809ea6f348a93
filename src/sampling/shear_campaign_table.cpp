#include "sampling/shear_campaign_table.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/random.hpp"

namespace trbc {
namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kStartSeedStream = 0x7368656172;  // "shear"

double fromUnit(const DesignAxis& a, double u) {
    return a.logScale ? a.lo * std::pow(a.hi / a.lo, u) : a.lo + u * (a.hi - a.lo);
}

std::string number(double x) { return std::isfinite(x) ? fmt::format("{:.17g}", x) : std::string("nan"); }

bool sameInputs(const ShearCampaignPoint& a, const ShearCampaignPoint& b) {
    const auto same = sameDesignValue;
    return a.caseId == b.caseId && same(a.cell.v, b.cell.v) && same(a.cell.mu, b.cell.mu) && same(a.cell.FvK, b.cell.FvK) &&
           same(a.cell.b2, b.cell.b2) && same(a.cell.etam, b.cell.etam) && same(a.etaOut, b.etaOut) &&
           same(a.shearRate, b.shearRate) && same(a.etaIn, b.etaIn) && a.startSeed == b.startSeed;
}

}  // namespace

std::vector<ShearCampaignPoint> shearCampaignDesign(DesignKind kind, long n, std::uint64_t seed, double etaIn) {
    const Eigen::MatrixXd u = unitDesign(kind, n, 7, seed);
    std::vector<ShearCampaignPoint> pts(static_cast<std::size_t>(n));
    for (long i = 0; i < n; ++i) {
        ShearCampaignPoint& q = pts[std::size_t(i)];
        double x[7];
        for (int j = 0; j < 7; ++j) x[j] = fromUnit(kShearCampaignAxes[j], u(i, j));
        q.caseId = i;
        q.cell = {x[0], x[1], x[2], x[3], x[4]};
        q.etaOut = x[5];
        q.shearRate = shearRateFromStress(x[5], x[6]);
        q.etaIn = etaIn;
        q.startSeed = Rng(seed, kStartSeedStream, std::uint64_t(i))();
    }
    return pts;
}

const std::string& shearCampaignCsvHeader() {
    static const std::string h =
        "case_id,v,mu_uN_per_m,FvK,b2,etam_Pa_s_um,eta_out_mPa_s,shear_rate_per_s,eta_in_mPa_s,start_seed,regime,"
        "inclination_deg,inclination_se_deg,swing_deg,swing_se_deg,ttf_4pi_f_over_rate,ttf_se,turns,steady,status,reason,wall_s";
    return h;
}

std::string formatShearCampaignRow(const ShearCampaignRow& r) {
    const ShearCampaignPoint& p = r.point;
    std::vector<std::string> f = {std::to_string(p.caseId), number(p.cell.v), number(p.cell.mu), number(p.cell.FvK),
                                  number(p.cell.b2), number(p.cell.etam), number(p.etaOut), number(p.shearRate),
                                  number(p.etaIn), std::to_string(p.startSeed), r.regime, number(r.inclinationDeg),
                                  number(r.inclinationSeDeg), number(r.swingDeg), number(r.swingSeDeg), number(r.ttf),
                                  number(r.ttfSe), number(r.turns), r.steady ? "1" : "0", r.status, r.reason,
                                  fmt::format("{:.3f}", r.wallSeconds)};
    std::string line = csvRow(f);
    line.pop_back();  // csvRow ends the line
    return line;
}

std::vector<ShearCampaignRow> readShearCampaignCsv(const fs::path& path, bool dropTornTail) {
    std::string text;
    {
        std::ifstream in(path, std::ios::binary);
        if (!in) throw InputError(fmt::format("cannot read the shear campaign table {}", path.string()));
        text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    if (dropTornTail && !text.empty() && text.back() != '\n') text.erase(text.rfind('\n') == std::string::npos ? 0 : text.rfind('\n') + 1);
    const auto records = parseCsvRecords(text);
    if (records.empty() || csvRow(records.front()) != shearCampaignCsvHeader() + "\n")
        throw InputError(fmt::format("{}: expected the header {}", path.string(), shearCampaignCsvHeader()));
    std::vector<ShearCampaignRow> rows;
    const std::size_t nf = records.front().size();
    for (std::size_t k = 1; k < records.size(); ++k) {
        const auto& f = records[k];
        const std::string where = fmt::format("{}: record {}", path.string(), k + 1);
        if (f.size() != nf) throw InputError(fmt::format("{}: {} fields, expected {}", where, f.size(), nf));
        auto num = [&](std::size_t i) {
            if (f[i] == "nan") return std::numeric_limits<double>::quiet_NaN();
            std::size_t used = 0;
            double x = 0.0;
            try {
                x = std::stod(f[i], &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used == 0 || used != f[i].size())
                throw InputError(fmt::format("{}: field {} '{}' is not a number", where, i + 1, f[i]));
            return x;
        };
        auto integer = [&](std::size_t i) {
            std::size_t used = 0;
            unsigned long long x = 0;
            try {
                x = std::stoull(f[i], &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used == 0 || used != f[i].size())
                throw InputError(fmt::format("{}: field {} '{}' is not a non-negative integer", where, i + 1, f[i]));
            return x;
        };
        ShearCampaignRow r;
        r.point.caseId = long(integer(0));
        r.point.cell = {num(1), num(2), num(3), num(4), num(5)};
        r.point.etaOut = num(6);
        r.point.shearRate = num(7);
        r.point.etaIn = num(8);
        r.point.startSeed = integer(9);
        r.regime = f[10];
        r.inclinationDeg = num(11), r.inclinationSeDeg = num(12), r.swingDeg = num(13), r.swingSeDeg = num(14);
        r.ttf = num(15), r.ttfSe = num(16), r.turns = num(17);
        if (f[18] != "0" && f[18] != "1") throw InputError(fmt::format("{}: steady '{}' is not 0 or 1", where, f[18]));
        r.steady = f[18] == "1";
        r.status = f[19];
        if (r.status != "ok" && r.status != "failed")
            throw InputError(fmt::format("{}: status '{}' is not ok or failed", where, r.status));
        r.reason = f[20];
        r.wallSeconds = num(21);
        rows.push_back(std::move(r));
    }
    return rows;
}

std::map<long, ShearCampaignRow> finishedShearCampaignRows(const fs::path& dir, const std::vector<ShearCampaignPoint>& design) {
    std::map<long, ShearCampaignRow> rows;
    if (!fs::exists(dir / "parts")) return rows;
    std::vector<fs::path> parts;
    for (const auto& entry : fs::directory_iterator(dir / "parts"))
        if (entry.path().extension() == ".csv" && fs::file_size(entry.path()) > 0) parts.push_back(entry.path());
    std::sort(parts.begin(), parts.end());
    for (const fs::path& part : parts)
        for (ShearCampaignRow& r : readShearCampaignCsv(part, true)) {
            const long id = r.point.caseId;
            if (id < 0 || id >= long(design.size()) || rows.count(id)) continue;
            if (!sameInputs(r.point, design[std::size_t(id)]))
                throw InputError(fmt::format("{}: case {} holds inputs other than the design's (eta_out {} against {}): the part "
                                             "files belong to another design or seed",
                                             part.string(), id, fmt::format("{:.17g}", r.point.etaOut), fmt::format("{:.17g}", design[std::size_t(id)].etaOut)));
            rows.emplace(id, std::move(r));
        }
    return rows;
}

nlohmann::json shearCampaignBoxJson() {
    nlohmann::json box = nlohmann::json::array();
    for (const DesignAxis& a : kShearCampaignAxes)
        box.push_back({{"name", a.name}, {"lo", a.lo}, {"hi", a.hi}, {"scale", a.logScale ? "log" : "linear"}});
    return box;
}

std::vector<ShearCampaignRow> readShearCampaignRows(const fs::path& path, bool* complete) {
    if (complete) *complete = true;
    if (fs::is_regular_file(path)) {
        // A campaign's own cases.csv takes the level of the campaign.json beside it.
        if (path.filename() == "cases.csv" && fs::exists(path.parent_path() / "campaign.json")) return readShearCampaignRows(path.parent_path(), complete);
        return readShearCampaignCsv(path);
    }
    if (!fs::is_directory(path)) throw InputError(fmt::format("shear campaign {} does not exist", path.string()));
    const fs::path provenance = path / "campaign.json";
    if (fs::exists(path / "cases.csv") && !fs::exists(provenance)) return readShearCampaignCsv(path / "cases.csv");
    DesignKind design = DesignKind::Sobol;
    long cases = 0;
    std::uint64_t seed = 0;
    double etaIn = 0.0;
    int level = 0;
    std::string start;
    nlohmann::json box;
    try {
        std::ifstream in(provenance);
        const nlohmann::json j = nlohmann::json::parse(in).at("settings");
        design = parseDesignKind(j.at("design").get<std::string>());
        cases = j.at("cases").get<long>();
        seed = j.at("seed").get<std::uint64_t>();
        etaIn = j.at("eta_in_mPa_s").get<double>();
        level = j.at("level").get<int>();
        start = j.value("start", std::string());
        box = j.value("box", nlohmann::json());
    } catch (const std::exception& e) {
        throw InputError(fmt::format("{}: not a shear campaign ({})", provenance.string(), e.what()));
    }
    std::vector<ShearCampaignRow> rows;
    if (fs::exists(path / "cases.csv")) {
        rows = readShearCampaignCsv(path / "cases.csv");
    } else {
        if (complete) *complete = false;
        // The finished rows are matched to the design this build makes, which another box moves.
        if (!box.is_null() && box != shearCampaignBoxJson())
            throw InputError(fmt::format("{}: the campaign was made on another design box ({}) than this build's ({}); its finished rows "
                                         "cannot be matched to this build's design",
                                         provenance.string(), box.dump(), shearCampaignBoxJson().dump()));
        for (auto& [id, r] : finishedShearCampaignRows(path, shearCampaignDesign(design, cases, seed, etaIn))) rows.push_back(std::move(r));
    }
    for (ShearCampaignRow& r : rows) r.meshLevel = level, r.start = start;
    return rows;
}

}  // namespace trbc
