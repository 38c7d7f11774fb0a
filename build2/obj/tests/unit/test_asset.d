build2/obj/tests/unit/test_asset.o: tests/unit/test_asset.c \
 common/base/asset.h
common/base/asset.h:
