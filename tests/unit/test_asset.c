/* Unit tests of scene asset access (common/base/asset.c): the lexical path rules, joining,
 * and the on-disk source (containment after realpath, so escaping symlinks are refused;
 * each file recorded once). Uses a fresh temporary folder per test. */
#include <criterion/criterion.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "base/asset.h"

static void expect_bad(const char *path, const char *why)
{
    char err[256] = "";
    cr_expect_eq(asset_path_check(path, err, sizeof err), -1, "\"%s\" accepted", path);
    cr_expect(strstr(err, why) != NULL, "\"%s\": error \"%s\" lacks \"%s\"", path, err, why);
}

Test(asset, path_check)
{
    char err[256];
    cr_expect_eq(asset_path_check("a.obj", err, sizeof err), 0);
    cr_expect_eq(asset_path_check("models/a b.obj", err, sizeof err), 0);
    cr_expect_eq(asset_path_check("..a/b..", err, sizeof err), 0);
    expect_bad("", "empty path");
    expect_bad("/etc/passwd", "absolute path");
    expect_bad("../x.obj", "\"..\" component");
    expect_bad("a/../../x.obj", "\"..\" component");
    expect_bad("a/..", "\"..\" component");
    expect_bad("./a.obj", "\".\" component");
    expect_bad("a//b.obj", "empty component");
    expect_bad("a/", "empty component");
    expect_bad("a\\..\\b", "backslash");
    expect_bad("a\nb", "control character");
    char longp[ASSET_PATH_MAX + 8];
    memset(longp, 'a', sizeof longp - 1);
    longp[sizeof longp - 1] = '\0';
    expect_bad(longp, "longer than");
}

Test(asset, path_join)
{
    char out[ASSET_PATH_MAX], err[256];
    cr_assert_eq(asset_path_join("", "a.mtl", out, sizeof out, err, sizeof err), 0);
    cr_expect_str_eq(out, "a.mtl");
    cr_assert_eq(asset_path_join("models/car", "car.mtl", out, sizeof out, err, sizeof err), 0);
    cr_expect_str_eq(out, "models/car/car.mtl");
    cr_expect_eq(asset_path_join("models", "../x.mtl", out, sizeof out, err, sizeof err), -1);
    cr_expect_eq(asset_path_join("models", "/x.mtl", out, sizeof out, err, sizeof err), -1);
    cr_expect_eq(asset_path_join("", "a.mtl", out, 4, err, sizeof err), -1);
}

static char g_tmp[256];

static void write_file(const char *rel, const char *text)
{
    char p[512];
    snprintf(p, sizeof p, "%s/%s", g_tmp, rel);
    FILE *f = fopen(p, "wb");
    cr_assert_not_null(f);
    fputs(text, f);
    fclose(f);
}

static void make_tmp(void)
{
    snprintf(g_tmp, sizeof g_tmp, "/tmp/brume_asset_XXXXXX");
    cr_assert_not_null(mkdtemp(g_tmp));
    char p[512];
    snprintf(p, sizeof p, "%s/scene", g_tmp);
    cr_assert_eq(mkdir(p, 0700), 0);
    snprintf(p, sizeof p, "%s/scene/sub", g_tmp);
    cr_assert_eq(mkdir(p, 0700), 0);
    write_file("secret.txt", "outside");
    write_file("scene/a.obj", "v 0 0 0\n");
    write_file("scene/sub/b.mtl", "newmtl b\n");
    char target[512], link[512];
    snprintf(target, sizeof target, "%s/secret.txt", g_tmp);
    snprintf(link, sizeof link, "%s/scene/escape.obj", g_tmp);
    cr_assert_eq(symlink(target, link), 0);
    snprintf(link, sizeof link, "%s/scene/inside.obj", g_tmp);
    cr_assert_eq(symlink("a.obj", link), 0);
    snprintf(link, sizeof link, "%s/scene/updir", g_tmp);
    cr_assert_eq(symlink("..", link), 0);
}

static void remove_tmp(void)
{
    char cmd[600];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_tmp);
    cr_expect_eq(system(cmd), 0);
}

TestSuite(asset_dir, .init = make_tmp, .fini = remove_tmp);

Test(asset_dir, reads_and_records_files)
{
    struct asset_dir dir;
    char err[512], folder[512];
    snprintf(folder, sizeof folder, "%s/scene", g_tmp);
    cr_assert_eq(asset_dir_init(&dir, folder, err, sizeof err), 0, "%s", err);
    struct asset_source src = asset_dir_source(&dir);
    char *data;
    size_t size;
    cr_assert_eq(src.read(src.ctx, "a.obj", &data, &size, err, sizeof err), 0, "%s", err);
    cr_expect_eq(size, 8);
    cr_expect_str_eq(data, "v 0 0 0\n");
    free(data);
    cr_assert_eq(src.read(src.ctx, "sub/b.mtl", &data, &size, err, sizeof err), 0, "%s", err);
    free(data);
    cr_assert_eq(src.read(src.ctx, "a.obj", &data, &size, err, sizeof err), 0, "%s", err);
    free(data);
    /* A symlink staying inside the folder is fine. */
    cr_assert_eq(src.read(src.ctx, "inside.obj", &data, &size, err, sizeof err), 0, "%s", err);
    free(data);
    cr_expect_eq(dir.num_files, 3);
    cr_expect_str_eq(dir.files[0].path, "a.obj");
    cr_expect_str_eq(dir.files[1].path, "sub/b.mtl");
    cr_expect_eq(dir.files[1].size, 9);
    cr_expect_str_eq(dir.files[2].path, "inside.obj");
    asset_dir_fini(&dir);
}

static void expect_read_fails(const char *rel, const char *why)
{
    struct asset_dir dir;
    char err[512], folder[512];
    snprintf(folder, sizeof folder, "%s/scene", g_tmp);
    cr_assert_eq(asset_dir_init(&dir, folder, err, sizeof err), 0, "%s", err);
    char *data = (char *)1;
    size_t size;
    cr_expect_eq(asset_dir_read(&dir, rel, &data, &size, err, sizeof err), -1, "%s was read", rel);
    cr_expect_null(data);
    cr_expect(strstr(err, why) != NULL, "%s: error \"%s\" lacks \"%s\"", rel, err, why);
    cr_expect_eq(dir.num_files, 0);
    asset_dir_fini(&dir);
}

Test(asset_dir, refuses_what_leaves_the_folder)
{
    expect_read_fails("missing.obj", "missing.obj: No such file");
    expect_read_fails("../secret.txt", "\"..\" component");
    expect_read_fails("/etc/passwd", "absolute path");
    expect_read_fails("escape.obj", "escape.obj: resolves outside the scene folder");
    expect_read_fails("updir/secret.txt", "updir/secret.txt: resolves outside the scene folder");
    expect_read_fails("sub", "sub: not a regular file");
}

Test(asset_dir, init_errors)
{
    struct asset_dir dir;
    char err[512], p[512];
    snprintf(p, sizeof p, "%s/nope", g_tmp);
    cr_expect_eq(asset_dir_init(&dir, p, err, sizeof err), -1);
    cr_expect(strstr(err, "nope") != NULL, "%s", err);
    snprintf(p, sizeof p, "%s/secret.txt", g_tmp);
    cr_expect_eq(asset_dir_init(&dir, p, err, sizeof err), -1);
    cr_expect(strstr(err, "not a directory") != NULL, "%s", err);
}

/* A FIFO would block open() until a writer came; it is refused at once instead. Criterion
 * times the test out (.timeout) rather than hang if it ever blocks again. */
Test(asset_dir, refuses_a_fifo_without_blocking, .timeout = 10)
{
    char p[512];
    snprintf(p, sizeof p, "%s/scene/pipe.png", g_tmp);
    cr_assert_eq(mkfifo(p, 0600), 0);
    expect_read_fails("pipe.png", "pipe.png: not a regular file (a FIFO)");
}

Test(asset_dir, a_signal_stops_reading)
{
    static atomic_int stop;
    stop = 1;
    asset_set_stop_flag(&stop);
    expect_read_fails("a.obj", "a.obj: interrupted");
    asset_set_stop_flag(NULL);
}

/* Output names against the files read: the same inode through a hard link or a symlink,
 * the same resolved path, and names that are no input (new or existing). */
Test(asset_dir, finds_a_read_file_by_any_name)
{
    struct asset_dir dir;
    char err[512], folder[512], p[512], q[512];
    snprintf(folder, sizeof folder, "%s/scene", g_tmp);
    cr_assert_eq(asset_dir_init(&dir, folder, err, sizeof err), 0, "%s", err);
    char *data;
    size_t size;
    cr_assert_eq(asset_dir_read(&dir, "sub/b.mtl", &data, &size, err, sizeof err), 0, "%s", err);
    free(data);
    snprintf(p, sizeof p, "%s/scene/sub/b.mtl", g_tmp);
    cr_expect_eq(asset_dir_find(&dir, p), 0);
    snprintf(p, sizeof p, "%s/scene/sub/../sub/b.mtl", g_tmp);
    cr_expect_eq(asset_dir_find(&dir, p), 0);
    snprintf(p, sizeof p, "%s/scene/sub/b.mtl", g_tmp);
    snprintf(q, sizeof q, "%s/hard.png", g_tmp);
    cr_assert_eq(link(p, q), 0);
    cr_expect_eq(asset_dir_find(&dir, q), 0, "a hard link to an input not found");
    snprintf(q, sizeof q, "%s/soft.png", g_tmp);
    cr_assert_eq(symlink(p, q), 0);
    cr_expect_eq(asset_dir_find(&dir, q), 0, "a symlink to an input not found");
    snprintf(p, sizeof p, "%s/scene/a.obj", g_tmp); /* exists, never read */
    cr_expect_eq(asset_dir_find(&dir, p), -1);
    snprintf(p, sizeof p, "%s/scene/new.exr", g_tmp);
    cr_expect_eq(asset_dir_find(&dir, p), -1);
    cr_expect_eq(asset_dir_find(&dir, "no/such/folder/x.exr"), -1);
    asset_dir_fini(&dir);
}

Test(asset, frame_name)
{
    char out[64];
    cr_expect_eq(asset_frame_name("smoke.####.nvdb", 7, out, sizeof out), 1);
    cr_expect_str_eq(out, "smoke.0007.nvdb");
    /* the last run only; a frame wider than the run is written in full */
    cr_expect_eq(asset_frame_name("a#/b##.grid", 123, out, sizeof out), 1);
    cr_expect_str_eq(out, "a#/b123.grid");
    cr_expect_eq(asset_frame_name("#", 0, out, sizeof out), 1);
    cr_expect_str_eq(out, "0");
    cr_expect_eq(asset_frame_name("smoke.nvdb", 7, out, sizeof out), 0);
    cr_expect_str_eq(out, "smoke.nvdb");
    cr_expect_eq(asset_frame_name("s.##########.nvdb", UINT32_MAX, out, sizeof out), 1);
    cr_expect_str_eq(out, "s.4294967295.nvdb");
    cr_expect_eq(asset_frame_name("smoke.####.nvdb", 7, out, 15), -1, "too small for the name and its NUL");
    cr_expect_eq(asset_frame_name("smoke.nvdb", 7, out, 10), -1);
}
