build-san/obj/common/asset.o: common/asset.c common/asset.h common/log.h
common/asset.h:
common/log.h:
