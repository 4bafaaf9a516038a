// tests/exr/exr_ref.cpp - reads an EXR with the OpenEXR library itself and
// compares its pixels with a PFM of the same image.  Built only where the
// library is installed (CI installs libopenexr-dev); appm never links it.
//
//   exr_ref FILE.exr FILE.pfm [half]
//
// Float files must match the PFM bit for bit; half files within the rounding of
// a half (relative 2^-11, or 2^-24 absolute near zero; values beyond 65504 are
// clamped to it by the writer).  Prints "exr_ref: ok WxH ..." and exits 0, or
// says what differs and exits 1.
#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfInputFile.h>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

static bool read_pfm(const char *path, int &w, int &h, std::vector<float> &rgb)
{
    FILE *f = std::fopen(path, "rb");
    char magic[3] = {0, 0, 0};
    double scale = 0;
    if (!f) return false;
    if (std::fscanf(f, "%2s %d %d %lf", magic, &w, &h, &scale) != 4 || std::strcmp(magic, "PF") != 0 ||
        std::fgetc(f) == EOF || w <= 0 || h <= 0 || scale >= 0) { // little-endian files only, as written on x86
        std::fclose(f);
        return false;
    }
    rgb.resize((size_t)w * h * 3);
    for (int y = h - 1; y >= 0; --y) // bottom row first
        if (std::fread(&rgb[(size_t)y * w * 3], sizeof(float), (size_t)w * 3, f) != (size_t)w * 3) {
            std::fclose(f);
            return false;
        }
    std::fclose(f);
    return true;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        std::fprintf(stderr, "usage: exr_ref FILE.exr FILE.pfm [half]\n");
        return 2;
    }
    bool half = argc > 3 && std::strcmp(argv[3], "half") == 0;
    int w, h;
    std::vector<float> ref;
    if (!read_pfm(argv[2], w, h, ref)) {
        std::fprintf(stderr, "exr_ref: cannot read %s\n", argv[2]);
        return 2;
    }
    try {
        Imf::InputFile in(argv[1]);
        Imath::Box2i dw = in.header().dataWindow();
        int ew = dw.max.x - dw.min.x + 1, eh = dw.max.y - dw.min.y + 1;
        if (ew != w || eh != h || dw.min.x != 0 || dw.min.y != 0) {
            std::fprintf(stderr, "exr_ref: %s is %dx%d, %s %dx%d\n", argv[1], ew, eh, argv[2], w, h);
            return 1;
        }
        const Imf::ChannelList &cl = in.header().channels();
        const char *names[3] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c) {
            const Imf::Channel *ch = cl.findChannel(names[c]);
            if (!ch || ch->type != (half ? Imf::HALF : Imf::FLOAT)) {
                std::fprintf(stderr, "exr_ref: channel %s missing or of the wrong type\n", names[c]);
                return 1;
            }
        }
        std::vector<float> px((size_t)w * h * 3);
        Imf::FrameBuffer fb;
        for (int c = 0; c < 3; ++c)
            fb.insert(names[c], Imf::Slice(Imf::FLOAT, (char *)&px[c], 3 * sizeof(float), 3 * sizeof(float) * w));
        in.setFrameBuffer(fb);
        in.readPixels(0, h - 1);
        size_t bad = 0, first = 0;
        for (size_t i = 0; i < px.size(); ++i) {
            float a = px[i], b = ref[i];
            bool same;
            if (!half) {
                same = std::memcmp(&a, &b, 4) == 0;
            } else {
                float bc = b > 65504.0f ? 65504.0f : b < -65504.0f ? -65504.0f : b;
                same = std::fabs(a - bc) <= std::fabs(bc) * (1.0f / 2048.0f) + 6.0e-8f;
            }
            if (!same && bad++ == 0) first = i;
        }
        if (bad) {
            std::fprintf(stderr, "exr_ref: %zu values differ; first at pixel (%zu, %zu) channel %zu: %.9g against %.9g\n",
                         bad, (first / 3) % w, first / 3 / w, first % 3, px[first], ref[first]);
            return 1;
        }
        std::printf("exr_ref: ok %dx%d %s %s\n", w, h, half ? "half" : "float",
                    in.header().compression() == Imf::ZIP_COMPRESSION ? "zip" : "none");
    } catch (const std::exception &e) {
        std::fprintf(stderr, "exr_ref: %s: %s\n", argv[1], e.what());
        return 1;
    }
    return 0;
}
