build-san/obj/tests/unit/test_asset.o: tests/unit/test_asset.c \
 common/asset.h
common/asset.h:
