build-san/obj/common/imgio.o: common/imgio.c common/imgio.h common/log.h
common/imgio.h:
common/log.h:
